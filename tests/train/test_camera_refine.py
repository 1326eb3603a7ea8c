"""Camera refinement in training (issue 44): the SE(3) correction against closed forms and finite differences,
perturbed cameras recovered by it, and the trainer's switch (its Adam group, schedule, checkpoint, refusal for the
field methods)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from eigs.artifacts.cameras import read_refined_cameras
from eigs.artifacts.run import CAMERAS
from eigs.errors import EigsError
from eigs.render.gaussians import render_gaussians
from eigs.render.rigid import se3_adjoint
from eigs.train.config import TrainConfig
from eigs.train.data import load_train_data
from eigs.train.gaussian.camera_refine import CameraRefinement
from eigs.train.gaussian.trainer import Trainer, train
from eigs.train.resolve import resolve_run
from eigs.util.schedule import exp_decay

F64 = torch.float64


def _hat(xi: torch.Tensor) -> torch.Tensor:
    """(6,) twist (ω, ν) → its (4, 4) matrix in se(3), for the matrix exponential."""
    w, v = xi[:3], xi[3:]
    m = torch.zeros(4, 4, dtype=xi.dtype)
    m[:3, :3] = torch.tensor([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]], dtype=xi.dtype)
    m[:3, 3] = v
    return m


def _look_at(eye: list[float]) -> torch.Tensor:
    """c2w (OpenCV axes) at ``eye`` looking at the origin, y down."""
    e = torch.tensor(eye, dtype=F64)
    z = -e / e.norm()
    x = torch.linalg.cross(z, torch.tensor([0.0, -1.0, 0.0], dtype=F64))
    x = x / x.norm()
    y = torch.linalg.cross(z, x)
    c2w = torch.eye(4, dtype=F64)
    c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = x, y, z, e
    return c2w


def _scene(n: int = 80, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    means = torch.randn(n, 3, generator=g, dtype=F64) * 0.5
    quats = torch.randn(n, 4, generator=g, dtype=F64)
    log_scales = torch.randn(n, 3, generator=g, dtype=F64) * 0.3 - 2.3
    opac = torch.randn(n, generator=g, dtype=F64) + 1.0
    sh = torch.rand(n, 1, 3, generator=g, dtype=F64)
    K = torch.tensor([[40.0, 0, 20], [0, 40.0, 15], [0, 0, 1]], dtype=F64)
    return means, quats, log_scales, opac, sh, K


def test_the_adjoint_conjugates_the_exponential():
    """T·exp(ξ)·T⁻¹ = exp(Ad_T ξ) against torch.linalg.matrix_exp, for rigid transforms far from the identity."""
    g = torch.Generator().manual_seed(7)
    for _ in range(4):
        t = torch.linalg.matrix_exp(_hat(torch.randn(6, generator=g, dtype=F64) * 1.5))
        xi = torch.randn(6, generator=g, dtype=F64) * 0.3
        lhs = t @ torch.linalg.matrix_exp(_hat(xi)) @ torch.linalg.inv(t)
        torch.testing.assert_close(torch.linalg.matrix_exp(_hat(se3_adjoint(t) @ xi)), lhs, atol=1e-13, rtol=0)


def _vee(m: torch.Tensor) -> torch.Tensor:
    """(4, 4) matrix in se(3) → its twist (ω, ν)."""
    return torch.stack([m[2, 1], m[0, 2], m[1, 0], m[0, 3], m[1, 3], m[2, 3]])


def _ring(n: int) -> torch.Tensor:
    """n cameras around the origin at similar distances, as a recording's views are."""
    return torch.stack([_look_at([2.8 * math.cos(a), 0.4 * math.sin(3 * a), 2.8 * math.sin(a)])
                        for a in torch.linspace(0.2, 2.6, n).tolist()])  # fmt: skip


def _gauge_directions(ref: torch.Tensor) -> list[torch.Tensor]:
    """The 13 directions of stacked camera-frame twists that move the reconstruction as a whole, built from the
    conjugation P⁻¹·ζ^·P (not from the adjoint the module uses): each world twist e_j, the scaling about the
    centroid, each common camera-frame twist e_j."""
    inv = torch.linalg.inv(ref)
    out = []
    for j in range(6):
        zeta = torch.zeros(6, dtype=F64)
        zeta[j] = 1.0
        out.append(torch.stack([_vee(inv[v] @ _hat(zeta) @ ref[v]) for v in range(len(ref))]))
    centroid = ref[:, :3, 3].mean(dim=0)
    out.append(torch.stack([_vee(inv[v] @ _hat(torch.cat([torch.zeros(3, dtype=F64), ref[v, :3, 3] - centroid]))
                                 @ ref[v]) for v in range(len(ref))]))  # fmt: skip
    for j in range(6):
        common = torch.zeros(len(ref), 6, dtype=F64)
        common[:, j] = 1.0
        out.append(common)
    return out


def test_the_correction_is_the_matrix_exponential_and_renders_the_corrected_camera():
    """Anchored twists are orthogonal to the 13 gauge directions, W_v⁻¹ = P_v·exp(−ξ_v)·P_v⁻¹ and the corrected
    camera P_v·exp(ξ_v) against torch.linalg.matrix_exp, and the moved Gaussians at P_v render exactly what the
    original ones render at the corrected camera (float64)."""
    ref = _ring(5)
    cam = CameraRefinement(ref, torch.device("cpu"), F64)
    torch.testing.assert_close(cam.world_motion(0), torch.eye(4, dtype=F64), atol=1e-15, rtol=0)  # η = 0: identity
    with torch.no_grad():
        cam.xi.copy_(torch.randn(5, 6, generator=torch.Generator().manual_seed(6), dtype=F64) * 0.03)
    xi = cam.twists().detach()
    assert (xi - cam.xi.detach()).abs().max() > 1e-3 and xi.abs().max() > 1e-3  # projected, a correction left
    for d in _gauge_directions(ref):
        assert abs(float((xi * d).sum())) < 1e-14 * float(d.norm())
    corrected = cam.corrected_c2w()
    means, quats, log_scales, opac, sh, K = _scene()
    for v in (0, 3):
        inv = torch.linalg.inv(ref[v])
        # se3_exp's Rodrigues coefficients are exact to ~1e-12 relative (eigs.render.rigid)
        torch.testing.assert_close(cam.world_motion(v), ref[v] @ torch.linalg.matrix_exp(-_hat(xi[v])) @ inv,
                                   atol=1e-10, rtol=0)  # fmt: skip
        torch.testing.assert_close(corrected[v], ref[v] @ torch.linalg.matrix_exp(_hat(xi[v])), atol=1e-10, rtol=0)
        moved_means, moved_quats = cam.move(v, means, quats)
        seen, _, _ = render_gaussians(moved_means, moved_quats, log_scales, opac, sh, ref[v], K, 40, 30)
        direct, _, _ = render_gaussians(means, quats, log_scales, opac, sh, corrected[v], K, 40, 30)
        assert direct.abs().max() > 0.1
        torch.testing.assert_close(seen, direct, atol=1e-9, rtol=0)


def test_a_motion_of_the_whole_reconstruction_is_not_learned():
    """Parameters along any gauge direction (a world motion, a scaling, a common camera-frame twist) leave every view
    uncorrected; parameters orthogonal to all of them pass unchanged, so the projection is idempotent; a view without
    a pose keeps its parameters and takes no part."""
    ref = torch.cat([_ring(6), torch.full((1, 4, 4), float("nan"), dtype=F64)])
    cam = CameraRefinement(ref, torch.device("cpu"), F64)
    directions = _gauge_directions(ref[:6])
    for d in directions:
        with torch.no_grad():
            cam.xi[:6] = 0.02 * d / d.abs().max()
            cam.xi[6] = 0.5
        for v in range(6):
            torch.testing.assert_close(cam.world_motion(v), torch.eye(4, dtype=F64), atol=1e-14, rtol=0)
        torch.testing.assert_close(cam.twists()[6], torch.full((6,), 0.5, dtype=F64), atol=0, rtol=0)
    basis = torch.stack([d.reshape(-1) for d in directions], dim=1)  # (36, 13)
    free = torch.randn(36, generator=torch.Generator().manual_seed(9), dtype=F64)
    free = free - basis @ torch.linalg.lstsq(basis, free[:, None]).solution[:, 0]  # orthogonal to every direction
    with torch.no_grad():
        cam.xi[:6] = (0.02 * free / free.abs().max()).reshape(6, 6)
    torch.testing.assert_close(cam.twists()[:6], cam.xi[:6].detach(), atol=1e-14, rtol=0)  # entries ~0.02


def test_the_gradient_of_the_moved_gaussians_matches_finite_differences():
    ref = _ring(4)
    cam = CameraRefinement(ref, torch.device("cpu"), F64)
    means, quats, *_ = _scene(12, seed=1)
    wm = torch.randn(4, 12, 3, dtype=F64, generator=torch.Generator().manual_seed(2))
    wq = torch.randn(4, 12, 4, dtype=F64, generator=torch.Generator().manual_seed(3))

    def f(xi: torch.Tensor) -> torch.Tensor:
        cam.xi = xi  # the parameters of every view are the checker's input
        out = 0
        for v in range(4):
            m, q = cam.move(v, means, quats)
            out = out + (m * wm[v]).sum() + (q * wq[v]).sum()
        return out

    start = torch.randn(4, 6, dtype=F64, generator=torch.Generator().manual_seed(4)) * 0.03
    for xi0 in (torch.zeros(4, 6, dtype=F64), start):
        assert torch.autograd.gradcheck(f, (xi0.clone().requires_grad_(True),), eps=1e-6, atol=1e-7)


def test_perturbed_cameras_move_back_toward_the_truth():
    """Six views around the Gaussians whose true cameras are their starting cameras moved by a correction outside
    the gauge directions (0.04 rad and 0.06 per view, less what the anchoring leaves to the Gaussians; worst error
    2.5° and 0.061, 2 % of the distance), trained with the Gaussians fixed: Adam on the twists alone (150 steps, lr
    1e-2 decaying to 1e-4) brings the worst rotation error to under a twentieth and the worst translation error too
    (measured: 0.002°, 0.00009)."""
    means, quats, log_scales, opac, sh, K = _scene(150, seed=4)
    log_scales = log_scales + 0.5  # larger Gaussians: an image that changes smoothly with the camera
    n = 6
    start = _ring(n)
    g = torch.Generator().manual_seed(5)
    dirs = torch.randn(n, 6, generator=g, dtype=F64)
    shift = torch.cat([0.04 * dirs[:, :3] / dirs[:, :3].norm(dim=1, keepdim=True),
                       0.06 * dirs[:, 3:] / dirs[:, 3:].norm(dim=1, keepdim=True)], dim=1).reshape(-1)  # fmt: skip
    basis = torch.stack([d.reshape(-1) for d in _gauge_directions(start)], dim=1)
    shift = (shift - basis @ torch.linalg.lstsq(basis, shift[:, None]).solution[:, 0]).reshape(n, 6)
    true = torch.stack([start[v] @ torch.linalg.matrix_exp(_hat(shift[v])) for v in range(n)])
    targets = [render_gaussians(means, quats, log_scales, opac, sh, c, K, 40, 30)[0] for c in true]
    cam = CameraRefinement(start, torch.device("cpu"), F64)
    opt = torch.optim.Adam([cam.xi], lr=1e-2)

    def errors() -> tuple[float, float]:
        rel = torch.linalg.inv(true) @ cam.corrected_c2w()
        rot = max(math.degrees(math.acos(min(1.0, (float(torch.trace(r[:3, :3])) - 1) / 2))) for r in rel)
        return rot, float(rel[:, :3, 3].norm(dim=1).max())

    rot0, tr0 = errors()
    for step in range(150):
        for group in opt.param_groups:
            group["lr"] = exp_decay(1e-2, 1e-4, step, 150)
        opt.zero_grad()
        loss = sum((render_gaussians(*cam.move(v, means, quats), log_scales, opac, sh, start[v], K, 40, 30)[0]
                    - targets[v]).abs().mean() for v in range(n))  # fmt: skip
        loss.backward()
        opt.step()
    rot1, tr1 = errors()
    assert rot1 < rot0 / 20 and tr1 < tr0 / 20, (rot0, rot1, tr0, tr1)


def test_the_schedule_decays_exponentially_between_its_ends():
    assert exp_decay(1e-3, 1e-6, 0, 100) == pytest.approx(1e-3, rel=1e-12)
    assert exp_decay(1e-3, 1e-6, 50, 100) == pytest.approx(math.sqrt(1e-3 * 1e-6), rel=1e-12)
    assert exp_decay(1e-3, 1e-6, 100, 100) == pytest.approx(1e-6, rel=1e-12)
    assert exp_decay(1e-3, 1e-6, 500, 100) == pytest.approx(1e-6, rel=1e-12)
    assert exp_decay(1e-3, 0.0, 50, 100) == pytest.approx(5e-4, rel=1e-12)


def test_the_switch_in_the_trainer(toy, tmp_path):
    """camera_refine adds the cameras' Adam group (decayed with the schedule), moves the twists of the views it
    trains, resumes them from a checkpoint exactly, and is refused for a radiance-field method."""
    data = load_train_data(*toy.paths())
    base = {"steps": 40, "eval_every": 0, "log_every": 20, "densify": False, "camera_refine": True,
            "checkpoint_every": 20}  # fmt: skip
    for method in ("3dgs", "eigs"):
        cfg = TrainConfig.from_dict({**base, "method": method})
        tr = Trainer(data, cfg, torch.device("cpu"))
        groups = {g["name"]: g for g in tr.optimizer.param_groups}
        assert groups["camera"]["weight_decay"] == cfg.camera_reg
        assert groups["camera"]["params"][0] is tr.method.camera.xi
        for _ in range(3):
            assert tr.train_step()
        assert groups["camera"]["lr"] == pytest.approx(exp_decay(cfg.lr_camera, cfg.lr_camera_final, 2, 40))
        moved = tr.method.camera.xi.detach().abs().sum(dim=1) > 0
        assert moved.any() and torch.isfinite(tr.method.camera.xi).all()
    cfg = TrainConfig.from_dict({**base, "method": "3dgs"})
    full = train(data, cfg, tmp_path / "full")
    train(data, cfg, tmp_path / "resumed", stop_after=30)
    resumed = train(data, cfg, tmp_path / "resumed")
    torch.testing.assert_close(resumed.method.camera.xi, full.method.camera.xi, rtol=0, atol=0)
    torch.testing.assert_close(resumed.model.params["means"], full.model.params["means"], rtol=0, atol=0)
    # the run folder holds the cameras before and after: after = before · exp(ξ), against torch's matrix exponential
    cams = read_refined_cameras(tmp_path / "full")
    xi = full.method.camera.twists().detach()
    np.testing.assert_array_equal(cams.twist, xi.numpy())
    np.testing.assert_array_equal(cams.views, np.isfinite(data.c2w[:, 0].numpy()).all(axis=(1, 2)))
    for v in np.flatnonzero(cams.views):
        expected = torch.from_numpy(cams.before[v]) @ torch.linalg.matrix_exp(_hat(xi[v]))
        np.testing.assert_allclose(cams.after[v], expected.numpy(), rtol=0, atol=1e-12)
    off = train(data, TrainConfig.from_dict({**base, "method": "3dgs", "camera_refine": False}), tmp_path / "off")
    assert off.method.camera is None and not (tmp_path / "off" / CAMERAS).exists()
    assert not torch.equal(off.model.params["means"], full.model.params["means"])
    with pytest.raises(EigsError, match="camera_refine.*field method"):
        resolve_run({"method": "e2nerf", "camera_refine": True})
