"""Camera trajectories (se(3) exp/log, curves, fits) and the trajectory methods (BAD-Gaussians, BeSplat,
EvaGaussians): closed forms, float64 references and behaviour on the toy scene."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from eigs.errors import EigsError
from eigs.losses.events import normalized_event_loss
from eigs.render.gaussians import render_gaussians
from eigs.render.rigid import se3_exp, se3_log, transform_gaussians
from eigs.train.config import TrainConfig
from eigs.train.data import load_train_data
from eigs.train.gaussian.trainer import Trainer
from eigs.train.gaussian.trajectory import curve_weights, fit_controls


def _rodrigues(w: np.ndarray) -> np.ndarray:
    th = np.linalg.norm(w)
    k = w / th
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(th) * kx + (1 - math.cos(th)) * kx @ kx


def test_se3_exp_matches_closed_forms():
    # pure rotation: Rodrigues; pure translation: identity rotation, t = ν
    w = np.array([0.3, -0.2, 0.5])
    t = se3_exp(torch.tensor([*w, 0, 0, 0], dtype=torch.float64)).numpy()
    np.testing.assert_allclose(t[:3, :3], _rodrigues(w), atol=1e-14)
    np.testing.assert_allclose(t[:3, 3], 0, atol=1e-15)
    t = se3_exp(torch.tensor([0, 0, 0, 1.0, -2.0, 3.0], dtype=torch.float64)).numpy()
    np.testing.assert_allclose(t, [[1, 0, 0, 1], [0, 1, 0, -2], [0, 0, 1, 3], [0, 0, 0, 1]], atol=1e-15)
    # a screw about z: rotation θ about z plus ν along z moves along z by ν exactly
    t = se3_exp(torch.tensor([0, 0, 0.7, 0, 0, 0.4], dtype=torch.float64)).numpy()
    np.testing.assert_allclose(t[:3, 3], [0, 0, 0.4], atol=1e-15)
    # exp(ξ) exp(−ξ) = I, and the matrix exponential of the 4×4 generator agrees
    xi = torch.tensor([0.1, 0.4, -0.3, 0.2, -0.5, 0.9], dtype=torch.float64)
    gen = torch.zeros(4, 4, dtype=torch.float64)
    gen[:3, :3] = torch.tensor([[0, 0.3, 0.4], [-0.3, 0, -0.1], [-0.4, 0.1, 0]], dtype=torch.float64)
    gen[:3, 3] = xi[3:]
    torch.testing.assert_close(se3_exp(xi), torch.linalg.matrix_exp(gen), atol=1e-13, rtol=0)
    torch.testing.assert_close(se3_exp(xi) @ se3_exp(-xi), torch.eye(4, dtype=torch.float64), atol=1e-14, rtol=0)


def test_se3_log_inverts_exp_and_small_angles_stay_finite():
    g = torch.Generator().manual_seed(0)
    xi = torch.randn(200, 6, generator=g, dtype=torch.float64)
    xi[:, :3] *= torch.rand(200, 1, generator=g, dtype=torch.float64) * 2.5  # angles up to ~2.5·√3 … keep < π
    xi = xi[xi[:, :3].norm(dim=1) < 3.0]
    torch.testing.assert_close(se3_log(se3_exp(xi)), xi, atol=1e-9, rtol=0)
    tiny = torch.tensor([[1e-9, -2e-9, 0, 0.1, 0, 0], [0, 0, 0, 0, 0, 0]], dtype=torch.float64, requires_grad=True)
    out = se3_exp(tiny)
    out.sum().backward()
    assert torch.isfinite(out).all() and torch.isfinite(tiny.grad).all()
    torch.testing.assert_close(se3_log(out.detach()), tiny.detach(), atol=1e-15, rtol=0)


@pytest.mark.parametrize("mode,k", [("linear", 2), ("cubic", 4), ("bezier", 2), ("bezier", 5)])
def test_curve_weights_partition_of_unity_and_fit(mode, k):
    u = torch.linspace(0, 1, 9, dtype=torch.float64)
    w = curve_weights(mode, k, u)
    torch.testing.assert_close(w.sum(1), torch.ones(9, dtype=torch.float64), atol=1e-15, rtol=0)
    assert (w >= -1e-15).all()
    # twists on a straight line in time are reproduced exactly by every curve (all contain linear functions)
    a, b = torch.randn(6, dtype=torch.float64), torch.randn(6, dtype=torch.float64)
    target = a + u[:, None] * b
    ctrl = fit_controls(mode, k, u, target, reg=0.0 if k <= 4 else 1e-12)
    torch.testing.assert_close(curve_weights(mode, k, u) @ ctrl, target, atol=1e-8, rtol=0)


def test_curve_weights_reject_wrong_control_counts():
    with pytest.raises(ValueError):
        curve_weights("linear", 3, torch.zeros(1))
    with pytest.raises(ValueError):
        curve_weights("cubic", 2, torch.zeros(1))
    with pytest.raises(ValueError):
        curve_weights("spline", 2, torch.zeros(1))


def test_normalized_event_loss_scale_free_and_bounded():
    g = torch.Generator().manual_seed(3)
    e = torch.randint(-3, 4, (12, 16), generator=g)
    a = torch.randn(12, 16, generator=g, dtype=torch.float64)
    assert normalized_event_loss(a, a + 0.37 * e, e).item() == pytest.approx(0.0, abs=1e-24)
    assert normalized_event_loss(a, a - 0.37 * e, e).item() == pytest.approx(4.0, abs=1e-12)  # opposite sign
    zero = normalized_event_loss(a, a.clone(), torch.zeros_like(e))
    assert torch.isfinite(zero) and zero.item() == 0.0
    mask = torch.zeros(12, 16, dtype=torch.bool)
    mask[0] = True
    b = a + 0.37 * e
    b[0] += 5.0  # a masked row disagrees: ignored
    assert normalized_event_loss(a, b, e, mask).item() == pytest.approx(0.0, abs=1e-24)


def test_camera_on_trajectory_equals_gaussians_moved_by_the_conjugate():
    """Rendering the camera P_ref·exp(ξ) equals rendering P_ref with the Gaussians moved by P_ref·exp(−ξ)·P_ref⁻¹."""
    g = torch.Generator().manual_seed(1)
    n = 50
    means = (torch.randn(n, 3, generator=g) * 0.4).double()
    quats = torch.randn(n, 4, generator=g).double()
    log_scales = (torch.randn(n, 3, generator=g) * 0.5 - 2.5).double()
    opac = torch.randn(n, generator=g).double()
    sh = torch.rand(n, 1, 3, generator=g).double()
    K = torch.tensor([[50.0, 0, 24], [0, 50.0, 18], [0, 0, 1]], dtype=torch.float64)
    ref = torch.eye(4, dtype=torch.float64)
    ref[:3, 3] = torch.tensor([0.1, -0.2, -3.0], dtype=torch.float64)
    xi = torch.tensor([0.02, -0.03, 0.05, 0.05, 0.02, -0.04], dtype=torch.float64)
    direct, _, _ = render_gaussians(means, quats, log_scales, opac, sh, ref @ se3_exp(xi), K, 48, 36)
    m2, q2 = transform_gaussians(means, quats, ref @ se3_exp(-xi) @ torch.linalg.inv(ref))
    moved, _, _ = render_gaussians(m2, q2, log_scales, opac, sh, ref, K, 48, 36)
    assert direct.abs().max() > 0.1
    torch.testing.assert_close(moved, direct, atol=1e-9, rtol=0)


@pytest.fixture(scope="module")
def data(toy):
    return load_train_data(*toy.paths())


def _trainer(data, method, steps=2, **opts):
    cfg = TrainConfig.from_dict({"method": method, "steps": steps, "eval_every": 0, "densify": False,
                                 "method_options": opts})  # fmt: skip
    return Trainer(data, cfg, torch.device("cpu"))


@pytest.mark.parametrize("method", ["bad-gaussians", "besplat", "evagaussians"])
def test_latent_init_reproduces_the_latent_poses_and_the_trajectory_gets_gradients(data, method):
    tr = _trainer(data, method)
    m = tr.method
    v = int(m.views[0])
    stride_times = torch.linspace(0, 1, m.n_virtual)
    # the Gaussian motion at u = k/N (where a virtual view sits there) undoes the relative latent pose P_0⁻¹P_k
    motions = m.gaussian_motions(v).detach().double()
    n_bins = data.n_latent - 1
    for k in range(data.n_latent):
        j = int(torch.argmin((stride_times - k / n_bins).abs()))
        if abs(float(stride_times[j]) - k / n_bins) > 1e-6 or not data.valid[v, k]:
            continue
        camera = torch.linalg.inv(motions[j]) @ m.ref[v]
        err_t = (camera[:3, 3] - data.c2w[v, k, :3, 3]).norm().item()
        assert err_t < 0.02 * max(data.c2w[v, k, :3, 3].norm().item(), 1.0), (k, err_t)
    out = m.step(tr.model, 0, 0, 0)
    out.loss.backward()
    assert m.controls.grad is not None and m.controls.grad[int(m.views[0])].abs().sum() > 0
    assert tr.model.params["means"].grad.abs().sum() > 0
    if method != "bad-gaussians":
        assert "event" in out.terms and math.isfinite(out.terms["event"])


@pytest.mark.parametrize("method", ["bad-gaussians", "besplat", "evagaussians"])
def test_a_view_sfm_did_not_register_is_left_out_not_a_singular_inverse(data, method):
    """SfM leaves some views unregistered (NaN latent poses, d346-blocks: 3 of 150 frames); a trajectory method
    trains on the others instead of failing on the batch inverse of its reference poses."""
    import dataclasses

    c2w, valid = data.c2w.clone(), data.valid.copy()
    c2w[1], valid[1] = float("nan"), False
    tr = _trainer(dataclasses.replace(data, c2w=c2w, valid=valid), method)
    m = tr.method
    assert 1 not in m.views.tolist() and m.n_samples() == data.n_views - 1
    assert torch.isfinite(m.ref_inv_f).all()
    torch.testing.assert_close(m.ref_inv_f[0].double(), torch.linalg.inv(c2w[0, 0]), atol=1e-5, rtol=1e-5)
    out = m.step(tr.model, 0, 0, 0)
    assert math.isfinite(out.loss.item())
    motion = m.latent_motion(tr.model.params["means"], tr.model.params["quats"])
    assert not motion.views[1] and torch.isfinite(motion.displacement[motion.views]).all()


def test_trajectory_options_checked(data):
    with pytest.raises(EigsError, match="multiple of the EDI bins"):
        _trainer(data, "besplat", n_virtual=6)
    with pytest.raises(EigsError, match="mode"):
        _trainer(data, "bad-gaussians", mode="spline")
    with pytest.raises(EigsError, match="control twists"):
        _trainer(data, "bad-gaussians", mode="cubic")


def test_trajectory_method_resumes_bit_identically(data, tmp_path):
    from eigs.train.gaussian.trainer import train

    cfg = TrainConfig.from_dict({"method": "bad-gaussians", "steps": 6, "eval_every": 0, "densify": False,
                                 "checkpoint_every": 3, "log_every": 1})  # fmt: skip
    full = train(data, cfg, tmp_path / "full")
    train(data, cfg, tmp_path / "resumed", stop_after=3)
    resumed = train(data, cfg, tmp_path / "resumed")
    torch.testing.assert_close(resumed.method.controls, full.method.controls, atol=0, rtol=0)
    assert (resumed.method.controls != tr_start(data)).any()  # the trajectory did move
    for name, t in full.model.params.items():
        torch.testing.assert_close(resumed.model.params[name], t, atol=0, rtol=0, msg=name)


def tr_start(data):
    return _trainer(data, "bad-gaussians").method.controls.detach()
