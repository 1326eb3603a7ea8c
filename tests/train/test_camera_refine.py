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


def test_the_correction_is_the_matrix_exponential_and_renders_the_corrected_camera():
    """Two views, only view 1's parameters non-zero (η): anchoring halves its world correction and gives view 0 the
    opposite one, so W_1⁻¹ = P₁·exp(−η/2)·P₁⁻¹ and W_0⁻¹ = P₁·exp(η/2)·P₁⁻¹, against torch.linalg.matrix_exp; and
    the moved Gaussians at P render exactly what the original ones render at the corrected camera (float64)."""
    ref = torch.stack([_look_at([0.3, -0.2, 3.0]), _look_at([-1.0, 0.1, 2.8])])
    cam = CameraRefinement(ref, torch.device("cpu"), F64)
    torch.testing.assert_close(cam.world_motion(0), torch.eye(4, dtype=F64), atol=1e-15, rtol=0)  # η = 0: identity
    eta = torch.tensor([0.03, -0.05, 0.02, 0.04, -0.01, 0.06], dtype=F64)
    with torch.no_grad():
        cam.xi[1] = eta
    p1, p1_inv = ref[1], torch.linalg.inv(ref[1])
    torch.testing.assert_close(cam.twists()[1], eta / 2, atol=1e-15, rtol=0)
    torch.testing.assert_close(cam.world_motion(1), p1 @ torch.linalg.matrix_exp(-_hat(eta / 2)) @ p1_inv,
                               atol=1e-14, rtol=0)  # fmt: skip
    torch.testing.assert_close(cam.world_motion(0), p1 @ torch.linalg.matrix_exp(_hat(eta / 2)) @ p1_inv,
                               atol=1e-14, rtol=0)  # fmt: skip
    corrected = cam.corrected_c2w()
    torch.testing.assert_close(corrected[1], p1 @ torch.linalg.matrix_exp(_hat(eta / 2)), atol=1e-14, rtol=0)
    means, quats, log_scales, opac, sh, K = _scene()
    for v in (0, 1):
        moved_means, moved_quats = cam.move(v, means, quats)
        seen, _, _ = render_gaussians(moved_means, moved_quats, log_scales, opac, sh, ref[v], K, 40, 30)
        direct, _, _ = render_gaussians(means, quats, log_scales, opac, sh, corrected[v], K, 40, 30)
        assert direct.abs().max() > 0.1
        torch.testing.assert_close(seen, direct, atol=1e-9, rtol=0)


def test_a_common_motion_of_every_camera_is_not_learned():
    """The gauge: parameters that move every posed camera by one world motion exp(ζ) (η_v = P_v⁻¹·ζ^·P_v, from the
    conjugation, not from the adjoint) leave every view uncorrected, and the world corrections of any parameters sum
    to zero; a view without a pose keeps its parameters and does not count."""
    ref = torch.stack([_look_at([0.3, -0.2, 3.0]), _look_at([-1.0, 0.1, 2.8]), _look_at([0.2, 0.9, 2.6]),
                       torch.full((4, 4), float("nan"), dtype=F64)])  # fmt: skip
    cam = CameraRefinement(ref, torch.device("cpu"), F64)
    zeta = torch.tensor([0.02, 0.03, -0.01, 0.05, -0.04, 0.02], dtype=F64)
    with torch.no_grad():
        for v in range(3):
            m = torch.linalg.inv(ref[v]) @ _hat(zeta) @ ref[v]
            cam.xi[v] = torch.stack([m[2, 1], m[0, 2], m[1, 0], m[0, 3], m[1, 3], m[2, 3]])
        cam.xi[3] = 0.5
    for v in range(3):
        torch.testing.assert_close(cam.world_motion(v), torch.eye(4, dtype=F64), atol=1e-14, rtol=0)
    torch.testing.assert_close(cam.twists()[3], torch.full((6,), 0.5, dtype=F64), atol=0, rtol=0)
    with torch.no_grad():
        cam.xi[:3] = torch.randn(3, 6, generator=torch.Generator().manual_seed(8), dtype=F64) * 0.05
    world = torch.stack([se3_adjoint(ref[v]) @ cam.twists()[v] for v in range(3)])
    assert world.abs().max() > 1e-3
    torch.testing.assert_close(world.sum(dim=0), torch.zeros(6, dtype=F64), atol=1e-15, rtol=0)


def test_the_gradient_of_the_moved_gaussians_matches_finite_differences():
    ref = torch.stack([_look_at([0.4, 0.3, 2.5]), _look_at([-0.5, 0.2, 2.7])])
    cam = CameraRefinement(ref, torch.device("cpu"), F64)
    means, quats, *_ = _scene(12, seed=1)
    wm = torch.randn(2, 12, 3, dtype=F64, generator=torch.Generator().manual_seed(2))
    wq = torch.randn(2, 12, 4, dtype=F64, generator=torch.Generator().manual_seed(3))

    def f(xi: torch.Tensor) -> torch.Tensor:
        cam.xi = xi  # the parameters of both views are the checker's input
        out = 0
        for v in (0, 1):
            m, q = cam.move(v, means, quats)
            out = out + (m * wm[v]).sum() + (q * wq[v]).sum()
        return out

    start = torch.tensor([[0.02, -0.04, 0.01, 0.03, 0.02, -0.05], [-0.01, 0.03, 0.02, -0.02, 0.04, 0.01]], dtype=F64)
    for xi0 in (torch.zeros(2, 6, dtype=F64), start):
        assert torch.autograd.gradcheck(f, (xi0.clone().requires_grad_(True),), eps=1e-6, atol=1e-7)


def test_perturbed_cameras_move_back_toward_the_truth():
    """Three views rendered at their true cameras, trained from cameras perturbed by 0.04 rad and 0.06 per view less
    their common world motion (worst 2.4° and 0.082, 3 % of the distance) with the Gaussians fixed: Adam on the twists
    alone (150 steps, lr 1e-2 decaying to 1e-4) brings the worst rotation error to under a twentieth and the worst
    translation error too (measured: 0.0007°, 0.00002)."""
    means, quats, log_scales, opac, sh, K = _scene(150, seed=4)
    log_scales = log_scales + 0.5  # larger Gaussians: an image that changes smoothly with the camera
    true = torch.stack([_look_at([0.5, -0.3, 2.6]), _look_at([-0.6, 0.2, 2.7]), _look_at([0.1, 0.6, 2.5])])
    targets = [render_gaussians(means, quats, log_scales, opac, sh, c, K, 40, 30)[0] for c in true]
    g = torch.Generator().manual_seed(5)
    dirs = torch.randn(3, 6, generator=g, dtype=F64)
    noise = torch.cat([0.04 * dirs[:, :3] / dirs[:, :3].norm(dim=1, keepdim=True),
                       0.06 * dirs[:, 3:] / dirs[:, 3:].norm(dim=1, keepdim=True)], dim=1)  # fmt: skip
    # without their common world motion (the gauge, which the anchored refinement leaves to the Gaussians)
    world = torch.stack([se3_adjoint(true[v]) @ noise[v] for v in range(3)])
    noise = torch.stack([torch.linalg.solve(se3_adjoint(true[v]), world[v] - world.mean(dim=0)) for v in range(3)])
    start = torch.stack([true[v] @ torch.linalg.matrix_exp(_hat(noise[v])) for v in range(3)])
    cam = CameraRefinement(start, torch.device("cpu"), F64)
    opt = torch.optim.Adam([cam.xi], lr=1e-2)

    def errors() -> tuple[float, float]:
        rel = torch.linalg.inv(true) @ cam.corrected_c2w()
        rot = max(math.degrees(math.acos(min(1.0, (float(torch.trace(r[:3, :3])) - 1) / 2))) for r in rel)
        return rot, float(rel[:, :3, 3].norm(dim=1).max())

    rot0, tr0 = errors()
    assert rot0 > 2.0 and tr0 > 0.055
    for step in range(150):
        for group in opt.param_groups:
            group["lr"] = exp_decay(1e-2, 1e-4, step, 150)
        opt.zero_grad()
        loss = sum((render_gaussians(*cam.move(v, means, quats), log_scales, opac, sh, start[v], K, 40, 30)[0]
                    - targets[v]).abs().mean() for v in range(3))  # fmt: skip
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
