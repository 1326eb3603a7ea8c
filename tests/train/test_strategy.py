"""Densification bookkeeping: Adam state follows clones, splits and prunes row by row; SH and model round trips."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from eigs.artifacts.gaussians import GaussianCloud
from eigs.errors import EigsError
from eigs.train.config import TrainConfig
from eigs.train.gaussian.model import GaussianModel, make_optimizer
from eigs.train.gaussian.strategy import DensifyStrategy, quat_to_rotmat, remap_gaussians


def _model(n: int = 6, channels: int = 3, degree: int = 1) -> GaussianModel:
    rng = np.random.default_rng(0)
    k = (degree + 1) ** 2 - 1
    cloud = GaussianCloud(
        means=rng.normal(size=(n, 3)).astype(np.float32),
        f_dc=rng.normal(size=(n, 3)).astype(np.float32),
        f_rest=rng.normal(size=(n, 3, k)).astype(np.float32),
        opacity=rng.normal(size=n).astype(np.float32),
        log_scales=rng.normal(-3, 0.5, size=(n, 3)).astype(np.float32),
        quats=rng.normal(size=(n, 4)).astype(np.float32),
    )
    return GaussianModel.from_cloud(cloud, degree, channels, torch.device("cpu"))


def _adam_step(model: GaussianModel, opt: torch.optim.Optimizer) -> None:
    loss = sum((t * torch.arange(1, t.numel() + 1, dtype=t.dtype).reshape(t.shape)).sum() ** 2 for t in
               model.params.values())  # fmt: skip
    opt.zero_grad()
    loss.backward()
    opt.step()


def test_remap_keeps_copies_and_zeroes_state_rows():
    model = _model()
    opt = make_optimizer(model, TrainConfig(), 1.0)
    _adam_step(model, opt)
    before = {n: (t.detach().clone(), opt.state[t]["exp_avg"].clone(), opt.state[t]["exp_avg_sq"].clone())
              for n, t in model.params.items()}  # fmt: skip
    keep = torch.tensor([0, 2, 5])
    new = {n: t.detach()[[1, 1]] * 0 + 7 for n, t in model.params.items()}
    remap_gaussians(model, opt, keep, new, new_state_from=torch.tensor([3, 4]))
    for n, t in model.params.items():
        p0, m0, v0 = before[n]
        assert t.shape[0] == 5 and t.requires_grad
        torch.testing.assert_close(t.detach()[:3], p0[keep])
        assert (t.detach()[3:] == 7).all()
        st = opt.state[t]
        torch.testing.assert_close(st["exp_avg"], torch.cat([m0[keep], m0[[3, 4]]]))
        torch.testing.assert_close(st["exp_avg_sq"], torch.cat([v0[keep], v0[[3, 4]]]))
        assert any(g["params"][0] is t for g in opt.param_groups)
    # zero state for new rows; the optimiser still steps
    remap_gaussians(model, opt, torch.arange(5), {n: t.detach()[:1] for n, t in model.params.items()})
    for t in model.params.values():
        assert (opt.state[t]["exp_avg"][5:] == 0).all()
    _adam_step(model, opt)


def test_refine_clones_small_splits_large_prunes_transparent():
    model = _model(n=6)
    cfg = TrainConfig(grow_grad2d=1e-3, grow_scale3d=0.1, prune_opacity=0.05, refine_start=1, refine_every=1)
    opt = make_optimizer(model, cfg, 1.0)
    _adam_step(model, opt)
    p = model.params
    with torch.no_grad():
        p["log_scales"][:] = math.log(0.01)  # small
        p["log_scales"][1] = math.log(0.5)  # large → split
        p["opacities"][:] = 3.0
        p["opacities"][4] = -6.0  # transparent → pruned
    ids = p["means"].detach().clone()
    m_avg = opt.state[p["means"]]["exp_avg"].clone()
    strat = DensifyStrategy(cfg, extent=1.0, width=100, height=80)
    strat.grad2d = torch.tensor([1.0, 1.0, 0.0, 0.0, 0.0, 0.0])  # 0 small+high → clone, 1 large+high → split
    strat.count = torch.ones(6)
    report = strat._refine(1, model, opt)
    assert (report.cloned, report.split, report.pruned) == (1, 1, 1)
    means = model.params["means"].detach()
    # 6 − 1 (split parent) + 1 (clone) + 2 (children) − 1 (pruned) = 7
    assert means.shape[0] == 7
    st = opt.state[model.params["means"]]["exp_avg"]
    for i in (0, 2, 3, 5):  # survivors keep their rows (found by position)
        row = torch.nonzero((means == ids[i]).all(dim=1)).squeeze(1)
        assert row.numel() >= 1
        torch.testing.assert_close(st[row[0]], m_avg[i])
    # the clone duplicates Gaussian 0 with its moments; split children sit near the parent with scales ÷ 1.6
    rows0 = torch.nonzero((means == ids[0]).all(dim=1)).squeeze(1)
    assert rows0.numel() == 2 and torch.equal(st[rows0[0]], st[rows0[1]])
    children = [r for r in range(7) if not any((means[r] == ids[i]).all() for i in range(6))]
    assert len(children) == 2
    for r in children:
        assert (st[r] == 0).all()
        torch.testing.assert_close(model.params["log_scales"].detach()[r], torch.full((3,), math.log(0.5 / 1.6)))
        assert (means[r] - ids[1]).norm() < 5 * 0.5
    assert not (means == ids[4]).all(dim=1).any()  # pruned
    for t in model.params.values():
        assert opt.state[t]["exp_avg"].shape == t.shape


def test_gradient_statistics_in_ndc_and_counted_once_per_step():
    model = _model(n=3)
    strat = DensifyStrategy(TrainConfig(), extent=1.0, width=200, height=100)
    m2d = torch.zeros(3, 2, requires_grad=True)
    m2d.grad = torch.tensor([[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]])
    radii = torch.tensor([[1, 1], [1, 1], [0, 0]], dtype=torch.int32)
    info = {"means2d": m2d, "radii": radii}
    strat.after_backward(model, [info, info])  # two renders in one step: gradients summed, counted once
    torch.testing.assert_close(strat.grad2d, torch.tensor([2 * 100.0, 2 * 50.0, 0.0]))
    torch.testing.assert_close(strat.count, torch.tensor([1.0, 1.0, 0.0]))


def _info(grad: list[list[float]], visible: list[bool]) -> dict:
    m2d = torch.zeros(len(grad), 2, requires_grad=True)
    m2d.grad = torch.tensor(grad)
    radii = torch.tensor([[int(v)] * 2 for v in visible], dtype=torch.int32)
    return {"means2d": m2d, "radii": radii}


def test_renders_that_pull_apart_cancel_in_the_vector_sum_not_in_the_norm_sum():
    """Three renders of one step, in pixels, W/2 = 100 and H/2 = 50: Gaussian 0 pulled (3, 4) then (−3, −4) then
    (0, 0) (cancels), Gaussian 1 (1, 0) three times (agrees), Gaussian 2 seen only in the last render (0, 2)."""
    model = _model(n=3)
    renders = [
        _info([[3.0, 4.0], [1.0, 0.0], [0.0, 0.0]], [True, True, False]),
        _info([[-3.0, -4.0], [1.0, 0.0], [0.0, 0.0]], [True, True, False]),
        _info([[0.0, 0.0], [1.0, 0.0], [0.0, 2.0]], [True, True, True]),
    ]
    stats = {}
    for mode in ("vector_sum", "norm_sum"):
        strat = DensifyStrategy(TrainConfig(grow_grad2d_renders=mode), extent=1.0, width=200, height=100)
        strat.after_backward(model, renders)
        torch.testing.assert_close(strat.count, torch.tensor([1.0, 1.0, 1.0]))
        stats[mode] = strat.grad2d
    ndc0 = math.hypot(3 * 100.0, 4 * 50.0)  # one render's pull on Gaussian 0, in NDC-scaled units
    torch.testing.assert_close(stats["vector_sum"], torch.tensor([0.0, 300.0, 100.0]))
    torch.testing.assert_close(stats["norm_sum"], torch.tensor([2 * ndc0, 300.0, 100.0]))


def test_a_non_finite_render_gradient_adds_nothing_in_either_statistic():
    model = _model(n=2)
    for mode in ("vector_sum", "norm_sum"):
        strat = DensifyStrategy(TrainConfig(grow_grad2d_renders=mode), extent=1.0, width=200, height=100)
        strat.after_backward(model, [_info([[math.nan, 0.0], [1.0, 0.0]], [True, True])] * 2)
        torch.testing.assert_close(strat.grad2d, torch.tensor([0.0, 200.0]))


def test_the_render_statistic_is_a_checked_choice():
    with pytest.raises(EigsError, match="grow_grad2d_renders"):
        TrainConfig.from_dict({"grow_grad2d_renders": "max"})


def test_quat_to_rotmat_is_orthonormal():
    q = torch.randn(50, 4, dtype=torch.float64)
    r = quat_to_rotmat(q)
    torch.testing.assert_close(r @ r.transpose(1, 2), torch.eye(3, dtype=torch.float64).expand(50, 3, 3))
    torch.testing.assert_close(torch.linalg.det(r), torch.ones(50, dtype=torch.float64))


def test_model_cloud_round_trip_colour_and_grey():
    model = _model(n=5, channels=3, degree=2)
    cloud = model.to_cloud()
    back = GaussianModel.from_cloud(cloud, 2, 3, torch.device("cpu"))
    for n in ("means", "sh0", "shN", "log_scales", "opacities"):
        torch.testing.assert_close(back.params[n], model.params[n])
    q = model.params["quats"].detach()
    torch.testing.assert_close(back.params["quats"], q / q.norm(dim=1, keepdim=True))
    grey = GaussianModel.from_cloud(cloud, 2, 1, torch.device("cpu"))
    assert grey.params["sh0"].shape == (5, 1, 1) and grey.params["shN"].shape == (5, 8, 1)
    torch.testing.assert_close(grey.params["sh0"][:, 0, 0], model.params["sh0"].detach()[:, 0, :].mean(dim=1))
    g_cloud = grey.to_cloud()
    assert g_cloud.f_dc.shape == (5, 3) and np.all(g_cloud.f_dc[:, 0] == g_cloud.f_dc[:, 2])
