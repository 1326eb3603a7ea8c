"""The multi-render methods (EiGS family, Deblurring-GS(+), E2GS): camera-delta identity, ADE gradients from each
loss, which parameters the ADE moves, and option checks."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from eigs.errors import EigsError
from eigs.losses import photometric_loss
from eigs.losses.consistency import motion_consistency_loss
from eigs.losses.events import event_integration_loss, log_intensity
from eigs.render.gaussians import render_gaussians
from eigs.render.rigid import quat_left_matrix, quat_multiply, rotmat_to_quat, transform_gaussians
from eigs.train.config import TrainConfig
from eigs.train.data import load_train_data
from eigs.train.gaussian.strategy import quat_to_rotmat
from eigs.train.gaussian.trainer import Trainer


@pytest.fixture(scope="module")
def data(toy):
    return load_train_data(*toy.paths())


def _random_rigid(g: torch.Generator) -> torch.Tensor:
    q = torch.cat([torch.ones(1, dtype=torch.float64), 0.1 * torch.randn(3, generator=g, dtype=torch.float64)])
    t = torch.eye(4, dtype=torch.float64)
    t[:3, :3] = quat_to_rotmat(q[None])[0]
    t[:3, 3] = torch.randn(3, generator=g, dtype=torch.float64) * 0.1
    return t


def test_moving_the_gaussians_by_the_inverse_equals_moving_the_camera():
    g = torch.Generator().manual_seed(0)
    n = 60
    means = (torch.randn(n, 3, generator=g) * 0.4 + torch.tensor([0.0, 0.0, 3.0])).double()
    quats = torch.randn(n, 4, generator=g).double()
    log_scales = (torch.randn(n, 3, generator=g) * 0.5 - 2.5).double()  # anisotropic
    opac = torch.randn(n, generator=g).double()
    sh = torch.rand(n, 1, 3, generator=g).double()
    K = torch.tensor([[50.0, 0, 24], [0, 50.0, 18], [0, 0, 1]], dtype=torch.float64)
    p0 = torch.eye(4, dtype=torch.float64)
    pk = p0 @ _random_rigid(g)
    direct, _, _ = render_gaussians(means, quats, log_scales, opac, sh, pk, K, 48, 36)
    rel = p0 @ torch.linalg.inv(pk)  # P_0 · P_k⁻¹
    m2, q2 = transform_gaussians(means, quats, rel)
    moved, _, _ = render_gaussians(m2, q2, log_scales, opac, sh, p0, K, 48, 36)
    assert direct.abs().max() > 0.1
    torch.testing.assert_close(moved, direct, atol=1e-9, rtol=0)


def test_a_stack_of_transforms_moves_the_gaussians_as_each_transform_alone():
    g = torch.Generator().manual_seed(2)
    means = torch.randn(50, 3, generator=g, dtype=torch.float64)
    quats = torch.randn(50, 4, generator=g, dtype=torch.float64)
    stack = torch.stack([_random_rigid(g) for _ in range(3)])  # (K, 4, 4)
    moved, rotated = transform_gaussians(means, quats, stack)
    assert moved.shape == (3, 50, 3) and rotated.shape == (3, 50, 4)
    for k in range(3):
        m, q = transform_gaussians(means, quats, stack[k])
        torch.testing.assert_close(moved[k], m, atol=1e-14, rtol=0)
        torch.testing.assert_close(rotated[k], q, atol=1e-14, rtol=0)
        r, t = stack[k, :3, :3], stack[k, :3, 3]
        torch.testing.assert_close(m, means @ r.T + t, atol=1e-14, rtol=0)  # R x + p, written out


def test_quaternion_helpers():
    g = torch.Generator().manual_seed(1)
    q = torch.randn(100, 4, generator=g, dtype=torch.float64)
    q = q / q.norm(dim=1, keepdim=True)
    q = torch.where(q[:, :1] < 0, -q, q)
    torch.testing.assert_close(rotmat_to_quat(quat_to_rotmat(q)), q)
    a, b = q[:50], q[50:]
    torch.testing.assert_close(quat_to_rotmat(quat_multiply(a, b)), quat_to_rotmat(a) @ quat_to_rotmat(b))


def _method(data, name, **options):
    cfg = TrainConfig.from_dict({"method": name, "densify": False, "method_options": options})
    return Trainer(data, cfg, torch.device("cpu"))


def test_ade_receives_gradients_from_each_loss(data):
    tr = _method(data, "eigs")
    m, model = tr.method, tr.model
    images, _, dx, latent = m.renders(model, int(m.views[0]), 0)
    stack = torch.stack(images)
    blur, _, _ = photometric_loss(stack.mean(0), m.blurry[int(m.views[0])])
    logs = log_intensity(stack[latent], m.response, m.events.mode)
    c = m.events.counts[int(m.views[0])]
    cp, cn = m.events.thresholds(int(m.views[0]))
    event = event_integration_loss(logs[0], logs[1], c[1] - c[0], cp, cn, m.events.mask)
    consis = motion_consistency_loss(model.params["means"].detach(), dx[:, 0])
    for name, loss in (("blur", blur), ("event", event), ("consistency", consis)):
        m.ade.zero_grad()
        loss.backward(retain_graph=True)
        grad = m.ade.first_x.weight.grad
        assert grad is not None and torch.isfinite(grad).all() and grad.abs().sum() > 0, name


@pytest.mark.parametrize(("name", "moves_shape"), [("deblurring-gs", False), ("deblurring-gs+", True)])
def test_which_parameters_the_ade_moves(data, name, moves_shape, monkeypatch):
    tr = _method(data, name)
    seen = []
    orig = tr.model.render

    def spy(*args, **kw):
        seen.append(sorted(k for k in ("means", "quats", "log_scales") if kw.get(k) is not None))
        return orig(*args, **kw)

    monkeypatch.setattr(tr.model, "render", spy)
    out = tr.method.step(tr.model, 0, 0, 0)
    assert torch.isfinite(out.loss)
    assert seen[0] == [] and len(seen) == data.n_latent
    want = ["log_scales", "means", "quats"] if moves_shape else ["means"]
    assert all(s == want for s in seen[1:])
    assert tr.method.ade.last.out_features == (data.n_latent - 1) * (10 if moves_shape else 3)


def test_subframes_interpolate_and_trapezoid_weights(data):
    tr = _method(data, "eigs", subframes=3, blur_weights="trapezoid", pose_prior=True)
    images, infos, dx, latent = tr.method.renders(tr.model, 0, 0)
    n = data.n_latent
    assert len(images) == 1 + 3 * (n - 1) and latent == [0, 3, 6, 9, 12][:n]
    w = tr.method.blur_weights(len(images))
    assert math.isclose(float(w.sum()), 1.0, abs_tol=1e-6) and w[0] == w[-1] == w[1] / 2
    assert torch.isfinite(tr.method.step(tr.model, 0, 0, 0).loss)


def test_e2gs_renders_the_latent_poses(data):
    tr = _method(data, "e2gs")
    images, _, dx, latent = tr.method.renders(tr.model, 0, 0)
    assert dx is None and tr.method.ade is None and latent == list(range(data.n_latent))
    direct, _, _ = tr.model.render(data.c2w[0, 2], tr.method.K, data.width, data.height, tr.method.background, 0)
    torch.testing.assert_close(images[2], direct)


def test_option_errors(data):
    with pytest.raises(EigsError, match="need the ADE"):
        _method(data, "e2gs", consistency=True)
    with pytest.raises(EigsError, match="event_loss"):
        _method(data, "eigs", event_loss="mse")
    with pytest.raises(EigsError, match="unknown option"):
        _method(data, "eigs", widht=3)
    with pytest.raises(EigsError, match="ade_precision"):
        _method(data, "eigs", ade_precision="float16")
    assert _method(data, "eigs", ade_precision="bfloat16").method.ade.matmul_dtype is torch.bfloat16
    assert _method(data, "eigs", ade_precision="float32").method.ade.matmul_dtype is None
    assert np.isfinite(_method(data, "eigs-minus").method.step(_method(data, "eigs-minus").model, 0, 0, 0).loss.item())


def test_discrete_blur_target_follows_the_latent_average(data):
    """With latents lin(L_k) = a_k · lin(B), the discrete target is mean(a_k) · lin(B) (inside the kept ratio band)
    and the blurry frame itself outside it; latents equal to the frame give the frame back."""
    import dataclasses

    from eigs.losses.events import from_linear, to_linear

    resp = data.camera_response
    lin_b = to_linear(data.blurry, resp)
    a = torch.tensor([0.9, 1.0, 1.1, 1.3, 1.7])[: data.n_latent]
    lat = from_linear(lin_b[:, None] * a.reshape(1, -1, 1, 1, 1), resp)
    d2 = dataclasses.replace(data, latent=lat)
    target = _method(d2, "eigs", blur_target="discrete").method.blurry
    expect_lin = lin_b * a.mean()
    band = (lin_b > 0.02) & (expect_lin < 1.0)  # no clipping of the scaled latents
    assert band.float().mean() > 0.5
    torch.testing.assert_close(to_linear(target, resp)[band], expect_lin[band], atol=2e-5, rtol=1e-4)
    same = _method(dataclasses.replace(data, latent=data.blurry[:, None].expand_as(data.latent)), "eigs",
                   blur_target="discrete").method.blurry  # fmt: skip
    torch.testing.assert_close(same, data.blurry, atol=2e-6, rtol=0)
    # a ratio outside [2/3, 3/2] keeps the blurry frame
    far = from_linear((lin_b * 2.0)[:, None].expand_as(data.latent), resp)
    kept = _method(dataclasses.replace(data, latent=far), "eigs", blur_target="discrete").method.blurry
    dark_or_far = lin_b > 0.02
    torch.testing.assert_close(kept[dark_or_far], data.blurry[dark_or_far], atol=0, rtol=0)
    with pytest.raises(EigsError, match="blur_target"):
        _method(data, "eigs", blur_target="discrete", subframes=2)


def test_discrete_floor_decides_which_dark_pixels_keep_the_blurry_frame(data):
    """Latents lin(L_k) = 1.1 · lin(B) (ratio 1.1, inside the band everywhere): pixels darker than the floor keep the
    frame, the others take 1.1 · lin(B); a floor of 0 corrects every pixel with light."""
    import dataclasses

    from eigs.losses.events import from_linear, to_linear

    resp = data.camera_response
    lin_b = to_linear(data.blurry, resp)
    lat = from_linear((lin_b * 1.1).clamp(max=1.0)[:, None].expand_as(data.latent), resp)
    d2 = dataclasses.replace(data, latent=lat)
    for floor in (0.0, 0.02, 0.2):
        target = to_linear(_method(d2, "eigs", blur_target="discrete", discrete_floor=floor).method.blurry, resp)
        dark, lit = lin_b <= floor, (lin_b > floor) & (lin_b * 1.1 < 1.0) & (lin_b > 0)
        assert bool(lit.any())
        torch.testing.assert_close(target[dark], lin_b[dark], atol=2e-6, rtol=0)
        torch.testing.assert_close(target[lit], 1.1 * lin_b[lit], atol=2e-5, rtol=1e-4)
    assert bool((lin_b <= 0.2).any()) and bool((lin_b > 0.2).any())
    with pytest.raises(EigsError, match="discrete_floor"):
        _method(data, "eigs", blur_target="discrete", discrete_floor=-0.1)


def test_zero_last_layer_starts_without_displacement(data):
    m = _method(data, "eigs", ade_zero_last=True).method
    x = torch.randn(30, 3)
    out = m.ade(x, m.pose_inputs[int(m.views[0])])
    assert out.abs().max().item() == 0.0
    assert m.ade.first_x.weight.abs().max().item() > 0  # only the last layer is zero


@pytest.mark.parametrize("name", ["eigs", "e2gs", "bad-gaussians", "besplat"])
def test_sharp_views_use_one_render(data, name):
    """A view EDI marks sharp is explained by one render at its reference pose (the photometric loss of that
    render against the frame); the others keep their N+1 (or n_virtual) renders; the switch turns it off."""
    import dataclasses

    sharp = np.zeros(data.n_views, bool)
    tr = _method(data, name)
    v0 = int(tr.method.views[0])
    sharp[v0] = True
    d2 = dataclasses.replace(data, edi=dataclasses.replace(data.edi, sharp=sharp))
    m = _method(d2, name).method
    model = _method(d2, name).model
    out = m.step(model, 0, 0, 0)
    assert len(out.infos) == 1 and set(out.terms) == {"l1", "dssim"}
    img, _, _ = model.render(d2.c2w[v0, 0], m.K, d2.width, d2.height, m.background, 0)
    expect, _, _ = photometric_loss(img, d2.blurry[v0], 0.2)
    torch.testing.assert_close(out.loss, expect)
    other = int(np.nonzero(np.isin(np.arange(d2.n_views), m.views) & ~sharp)[0][0])
    sample = int(np.nonzero(m.views == other)[0][0])
    assert len(m.step(model, sample, 0, 0).infos) > 1
    off = _method(d2, name, sharp_one_render=False).method
    assert len(off.step(model, 0, 0, 0).infos) > 1


def test_latent_weight_adds_the_l1_of_each_latent_render_to_its_edi_frame(data):
    """The step's extra term is the mean |render_k − EDI latent_k| over the latent times with a pose (computed here
    from the method's own renders), times ``latent_weight``; off (0) it is absent."""
    w = 0.5
    tr = _method(data, "eigs-minus", latent_weight=w, consistency=False)
    m, model = tr.method, tr.model
    sample = 0
    v = int(m.views[sample])
    images, _, _, pos = m.renders(model, v, 0)
    stack = torch.stack(images)[pos]
    ok = torch.from_numpy(data.valid[v])
    expect = (stack[ok] - data.latent[v][ok]).abs().mean()
    out = m.step(model, sample, 0, 0)
    torch.testing.assert_close(torch.tensor(out.terms["latent"]), expect.detach(), atol=1e-6, rtol=1e-5)
    base = _method(data, "eigs-minus", consistency=False)
    out0 = base.method.step(base.model, sample, 0, 0)
    assert "latent" not in out0.terms
    torch.testing.assert_close(out.loss, out0.loss + w * expect, atol=1e-6, rtol=1e-5)
    with pytest.raises(EigsError, match="latent_weight"):
        _method(data, "eigs", latent_weight=-1.0)


def test_latent_dssim_adds_the_photometric_loss_of_each_latent_render(data):
    """With ``latent_dssim`` the latent term is (1 − λ)·L1 + λ·(1 − SSIM) of each latent render against its EDI
    frame, averaged over the latent times with a pose: computed here one frame at a time, from the method's renders."""
    from eigs.metrics.pixel import ssim_torch

    w = 2.0
    tr = _method(data, "eigs-minus", latent_weight=w, latent_dssim=True, consistency=False)
    m, model = tr.method, tr.model
    lam = tr.cfg.lambda_dssim
    assert lam > 0
    v = int(m.views[0])
    images, _, _, pos = m.renders(model, v, 0)
    stack = torch.stack(images)[pos].detach().double()
    target = data.latent[v].double()
    per_frame = [(1 - lam) * (stack[k] - target[k]).abs().mean()
                 + lam * (1 - ssim_torch(stack[k].permute(2, 0, 1), target[k].permute(2, 0, 1)))
                 for k in np.nonzero(data.valid[v])[0]]  # fmt: skip
    expect = torch.stack(per_frame).mean()
    out = m.step(model, 0, 0, 0)
    torch.testing.assert_close(torch.tensor(out.terms["latent"], dtype=torch.float64), expect, atol=1e-6, rtol=1e-5)
    l1_only = _method(data, "eigs-minus", latent_weight=w, consistency=False)
    out1 = l1_only.method.step(l1_only.model, 0, 0, 0)
    torch.testing.assert_close(out.loss - w * out.terms["latent"], out1.loss - w * out1.terms["latent"],
                               atol=1e-6, rtol=1e-5)  # the other terms unchanged


def test_latent_weight_dark_takes_over_only_where_ssim_cannot_see_the_texture(data):
    """``latent_weight_dark`` replaces ``latent_weight`` on a scene whose blurry frames' texture is below
    DARK_TEXTURE × C2 (eigs.metrics.texture), and the run is then the run configured with that weight: the same
    step, bit for bit. The toy's frames are bright; darkened by k, their local variance drops by k²."""
    import dataclasses

    from eigs.metrics.texture import DARK_TEXTURE, ssim_texture_visibility

    bright = ssim_texture_visibility(data.blurry)
    assert bright > DARK_TEXTURE
    k = (0.5 * DARK_TEXTURE / bright) ** 0.5
    dark = dataclasses.replace(data, blurry=data.blurry * k)
    assert ssim_texture_visibility(dark.blurry) == pytest.approx(0.5 * DARK_TEXTURE, rel=1e-5)
    for scene, expect in ((data, 0.5), (dark, 2.0)):
        auto = _method(scene, "eigs-minus", latent_weight=0.5, latent_weight_dark=2.0, latent_dssim=True)
        fixed = _method(scene, "eigs-minus", latent_weight=expect, latent_dssim=True)
        assert auto.method.latent_weight == expect
        a, b = auto.method.step(auto.model, 0, 0, 0), fixed.method.step(fixed.model, 0, 0, 0)
        assert torch.equal(a.loss, b.loss) and a.terms == b.terms
    off = _method(dark, "eigs-minus", latent_weight=0.5)  # latent_weight_dark 0 (the default): no switch
    assert off.method.latent_weight == 0.5
    with pytest.raises(EigsError, match="latent_weight_dark"):
        _method(data, "eigs", latent_weight_dark=-1.0)


@pytest.mark.parametrize(
    ("name", "options"),
    [("e2gs", {}), ("eigs", {"pose_prior": True, "ade_zero_last": True}),
     ("bad-gaussians", {"mode": "bezier", "n_control": 5})],  # 5 controls through 5 latent poses: an exact fit
)  # fmt: skip
def test_latent_motion_is_the_rigid_motion_of_the_latent_poses_at_start(data, name, options):
    """At step 0 the motion a method exports equals P_0·P_k⁻¹ x − x computed here in float64: e2gs renders the latent
    poses; EiGS with the pose prior and a zero last layer has no residual; a trajectory with as many control twists
    as latent poses starts through them."""
    tr = _method(data, name, **options)
    p = tr.model.params
    x, q = p["means"].detach()[:50], p["quats"].detach()[:50]
    m = tr.method.latent_motion(x, q)
    assert m.displacement.shape == (data.n_views, data.n_latent - 1, 50, 3)
    v = int(tr.method.views[0])
    for k in range(1, data.n_latent):
        a = data.c2w[v, 0] @ torch.linalg.inv(data.c2w[v, k])
        expect = x.double() @ a[:3, :3].T + a[:3, 3] - x.double()
        torch.testing.assert_close(m.displacement[v, k - 1].double(), expect, atol=2e-5, rtol=0)
        if m.camera_c2w is not None:
            torch.testing.assert_close(m.camera_c2w[v, k - 1], data.c2w[v, k], atol=1e-5, rtol=0)
    assert (m.camera_c2w is None) == (name == "eigs")


@pytest.mark.parametrize(("name", "options"), [("e2gs", {}), ("eigs", {"pose_prior": True})])
def test_a_view_sfm_did_not_register_exports_no_motion_and_the_run_writes(data, name, options, tmp_path):
    """A whole view without poses (d346-blocks: view 10's five latent frames unregistered): training leaves it out
    and its exported motion is zero, not the NaN of its poses, so the run's motion.npz validates and is written."""
    import dataclasses

    from eigs.artifacts.motion import RunMotion, write_motion

    c2w, valid = data.c2w.clone(), data.valid.copy()
    c2w[1], valid[1] = float("nan"), False
    tr = _method(dataclasses.replace(data, c2w=c2w, valid=valid), name, **options)
    p = tr.model.params
    x, q = p["means"].detach()[:50], p["quats"].detach()[:50]
    m = tr.method.latent_motion(x, q)
    assert not m.views[1] and m.views.sum() == data.n_views - 1
    assert torch.isfinite(m.displacement).all() and (m.displacement[1] == 0).all()
    assert m.displacement[m.views].abs().sum() > 0  # the others keep their motion
    run = RunMotion(name, x.numpy(), m.displacement.numpy(), m.reference_c2w.numpy(), m.views,
                    None if m.camera_c2w is None else m.camera_c2w.numpy())  # fmt: skip
    write_motion(run, tmp_path / "motion.npz")  # validates: raised "displacement has NaN/Inf values" before


def test_methods_without_motion_export_none(data):
    tr = _method(data, "edi-3dgs")
    p = tr.model.params
    assert tr.method.latent_motion(p["means"], p["quats"]) is None


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU (bench/gpu_check.sh runs it)")
def test_eigs_plus_steps_on_cuda(data):
    """Every tensor of an eigs+ step lives on the model's device (the blur weights and the latent mask were made on
    the CPU once: the first CUDA run of eigs+ stopped at its first step)."""
    opts = {"pose_prior": True, "ade_zero_last": True, "blur_target": "discrete", "blur_weights": "trapezoid",
            "latent_weight": 0.5}  # fmt: skip
    cfg = TrainConfig.from_dict({"method": "eigs", "densify": False, "method_options": opts})
    tr = Trainer(data, cfg, torch.device("cuda"))
    moving = [i for i, v in enumerate(tr.method.views) if not bool(tr.method.events.sharp[int(v)])]
    out = tr.method.step(tr.model, moving[0], 0, 0)
    out.loss.backward()
    assert torch.isfinite(out.loss) and out.loss.device.type == "cuda"


def test_quat_left_matrix_is_the_hamilton_product() -> None:
    """L(a) b equals a ⊗ b (transform_gaussians rotates through L), float64, batched."""
    g = torch.Generator().manual_seed(3)
    a, b = torch.randn(2, 50, 4, generator=g, dtype=torch.float64)
    got = (quat_left_matrix(a) @ b.unsqueeze(-1)).squeeze(-1)
    torch.testing.assert_close(got, quat_multiply(a, b), rtol=1e-14, atol=1e-14)
