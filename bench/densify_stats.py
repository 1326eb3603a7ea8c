"""Why the multi-render methods grow fewer Gaussians (issue 43, part 3): the screen-space gradients that decide
densification, per method and image size.

Densification (:class:`eigs.train.gaussian.strategy.DensifyStrategy`) clones or splits a Gaussian whose mean
screen-space gradient, in NDC units, exceeds ``grow_grad2d`` (5e-4). A step that renders several images (the B + 1
latent renders of EiGS, a trajectory method's sub-frames) sums the renders' ``means2d`` gradients per Gaussian as
vectors and takes the norm of the sum. This script trains each run of a config on a scene's artifacts (its own
budget, or ``--steps``) and records, per Gaussian and step, from the same gradients:

- ``‖Σ g‖``: the norm of the summed vectors (what the strategy accumulates today);
- ``Σ ‖g‖``: the sum of the renders' norms (each render's pull, without the cancellation between renders);
- ``max ‖g‖``: the largest single render's norm;

each averaged over the steps in which the Gaussian was visible, as the strategy averages, over each refinement's
window (the strategy's accumulators restart after every refinement). Reported per run: renders per step, over the
windows the mean fraction of Gaussians above ``grow_grad2d`` under each statistic (what each refinement grows, or
would grow), the median of each over the windows' Gaussians, the cancellation ``‖Σ g‖ / Σ ‖g‖`` (median; 1 for one
render), and the Gaussians at the first refinement, at the end of growth and at the end.

Run: ``.venv/bin/python bench/densify_stats.py --results results/chair --config config/config.yaml --runs 3dgs
edi-3dgs oracle e2gs eigs eigs+ [--bins 4] [--steps N] [--threads 2] [--out DIR]``; sections are named by the
scene (``densify-stats-<scene>``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import torch
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench._report import add_out_argument, table, write_section  # noqa: E402
from eigs.train.config import TrainConfig  # noqa: E402
from eigs.train.data import load_train_data  # noqa: E402
from eigs.train.gaussian.trainer import Trainer  # noqa: E402

STATS = ("sum_norm", "norm_sum", "max_norm")


class GradientRecorder:
    """Per-Gaussian sums of the three statistics and the visible-step count, fed with each step's render infos."""

    def __init__(self, n: int, half: tuple[float, float]):
        self.half = torch.tensor(half, dtype=torch.float32)
        self.sums = {k: torch.zeros(n, dtype=torch.float64) for k in STATS}
        self.count = torch.zeros(n, dtype=torch.float64)
        self.renders: list[int] = []

    def add(self, infos: list[dict]) -> None:
        n = self.count.shape[0]
        vec = torch.zeros(n, 2)
        norm_sum = torch.zeros(n)
        max_norm = torch.zeros(n)
        visible = torch.zeros(n, dtype=torch.bool)
        used = 0
        for info in infos:
            m2d = info["means2d"]
            if m2d.grad is None:
                continue
            used += 1
            g = m2d.grad.detach().reshape(n, 2).to(torch.float32).cpu() * self.half  # NDC, as the strategy
            norm = g.norm(dim=-1).nan_to_num(0.0, 0.0, 0.0)
            vec += g.nan_to_num(0.0, 0.0, 0.0)
            norm_sum += norm
            max_norm = torch.maximum(max_norm, norm)
            visible |= (info["radii"].reshape(n, -1) > 0).any(dim=-1).cpu()
        self.renders.append(used)
        for key, value in (("sum_norm", vec.norm(dim=-1)), ("norm_sum", norm_sum), ("max_norm", max_norm)):
            self.sums[key] += torch.where(visible, value, torch.zeros_like(value)).double()
        self.count += visible.double()

    def summary(self, threshold: float) -> dict[str, float]:
        seen = self.count > 0
        out: dict[str, float] = {"gaussians": int(self.count.shape[0]), "seen": int(seen.sum())}
        means = {k: (v[seen] / self.count[seen]) for k, v in self.sums.items()}
        for key, m in means.items():
            out[f"{key}_above"] = float((m > threshold).double().mean()) if m.numel() else float("nan")
            out[f"{key}_median"] = float(m.median()) if m.numel() else float("nan")
        ratio = means["sum_norm"] / means["norm_sum"].clamp_min(1e-30)
        out["cancellation_median"] = float(ratio.median()) if ratio.numel() else float("nan")
        out["renders_per_step"] = sum(self.renders) / max(len(self.renders), 1)
        return out


def measure(data, run: dict, steps: int | None) -> dict[str, float]:  # noqa: ANN001
    """Train ``run`` (its config entry: method and options) for its budget (or ``steps``) with every step's gradients
    recorded and summarised at each refinement; the means over the refinement windows."""
    cfg = TrainConfig.from_dict({"method": run["method"], **run.get("options", {}), "eval_every": 0})
    steps = cfg.steps if steps is None else steps
    tr = Trainer(data, cfg, torch.device("cpu"))
    half = (data.width / 2.0, data.height / 2.0)
    rec = [GradientRecorder(len(tr.model), half)]
    windows: list[dict[str, float]] = []
    sizes: list[int] = []
    after_backward, after_step = tr.strategy.after_backward, tr.strategy.after_step

    def recording_backward(model, infos):  # noqa: ANN001, ANN202
        if rec[0].count.shape[0] != len(model):
            rec[0] = GradientRecorder(len(model), half)
        rec[0].add(infos)
        return after_backward(model, infos)

    def recording_step(step, model, optimizer):  # noqa: ANN001, ANN202
        n = len(model)
        report = after_step(step, model, optimizer)
        # the strategy's own condition for a refinement (its accumulators restart after it)
        if cfg.densify and cfg.refine_start <= step < cfg.refine_stop and step % cfg.refine_every == 0:
            windows.append(rec[0].summary(cfg.grow_grad2d))
            sizes.append(n)
            rec[0] = GradientRecorder(len(model), half)
        return report

    tr.strategy.after_backward = recording_backward
    tr.strategy.after_step = recording_step
    t0 = time.perf_counter()
    for _ in range(steps):
        tr.train_step()
    if not windows:  # no refinement within the steps: the one window so far
        windows.append(rec[0].summary(cfg.grow_grad2d))
        sizes.append(len(tr.model))
    out = {k: sum(w[k] for w in windows) / len(windows) for k in windows[0] if k not in ("gaussians", "seen")}
    out |= {"windows": len(windows), "gaussians_first": sizes[0], "gaussians_end": len(tr.model),
            "seconds": time.perf_counter() - t0, "threshold": cfg.grow_grad2d, "steps": steps}  # fmt: skip
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--results", type=Path, required=True, help="a scene's results folder (results/<scene>)")
    ap.add_argument("--config", type=Path, required=True, help="the config whose runs: entries are measured")
    ap.add_argument("--runs", nargs="+", required=True)
    ap.add_argument("--bins", type=int, default=4)
    ap.add_argument("--steps", type=int, default=None, help="steps instead of each run's budget")
    ap.add_argument("--threads", type=int, default=2)
    add_out_argument(ap)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    runs = yaml.safe_load(args.config.read_text())["runs"]
    b = args.results / f"b{args.bins}"
    data = load_train_data(args.results / "scene.h5", b / "edi.h5", b / "sfm", b / "init.ply")
    got = {}
    for name in args.runs:
        got[name] = measure(data, runs[name], args.steps)
        print(name, {k: round(v, 6) if isinstance(v, float) else v for k, v in got[name].items()}, flush=True)
    scene = args.results.name
    rows = [[f"`{n}`", g["steps"], g["renders_per_step"], g["windows"], 100 * g["sum_norm_above"],
             100 * g["norm_sum_above"], 100 * g["max_norm_above"], 1e4 * g["sum_norm_median"],
             1e4 * g["norm_sum_median"], 1e4 * g["max_norm_median"], g["cancellation_median"], g["gaussians_first"],
             g["gaussians_end"]] for n, g in got.items()]  # fmt: skip
    body = (
        f"Scene `{scene}` ({data.width}×{data.height}, B = {args.bins}, each run's own options and budget, "
        f"{args.threads} thread(s); `bench/densify_stats.py`). Per Gaussian, the mean over its visible steps of a "
        "refinement window of the screen-space gradient in NDC: ‖Σ g‖ (summed over the step's renders, then the "
        "norm: what densification uses), Σ ‖g‖ (each render's norm, summed) and max ‖g‖ (the largest render's). "
        "'% above': the share of the window's seen Gaussians above `grow_grad2d` (5e-4), what the refinement grows "
        "under each statistic, averaged over the windows; medians in units of 1e-4, averaged likewise; "
        "'cancellation' the median of ‖Σ g‖ / Σ ‖g‖; Gaussians at the first refinement and at the end.\n\n"
        + table(["run", "steps", "renders / step", "windows", "% above ‖Σ g‖", "% above Σ ‖g‖", "% above max ‖g‖",
                 "median ‖Σ g‖", "median Σ ‖g‖", "median max ‖g‖", "cancellation", "Gaussians first",
                 "Gaussians end"], rows)  # fmt: skip
    )
    write_section(f"densify-stats-{scene}", f"Densification gradients per method: {scene} (issue 43)", body,
                  data=got, out=args.out)  # fmt: skip


if __name__ == "__main__":
    main()
