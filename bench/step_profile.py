"""Where one training step goes at a scene's own image size (issue 32, part 5: 346×260).

Writes the "step-profile" section of docs/benchmarks.md: for each named run of a config, one step on the scene's
artifacts (its own size, the init cloud resampled to ``--gaussians``, no densification) split into the renders'
forward, the rasterizer's backward, the projection's backward, the rest of the backward (ADE network, losses,
trajectories), the rest of the forward and Adam. The wall split comes from ``bench/train.py``'s
``method_breakdown``; the rasterizer's and projection's backward from torch.profiler (the self time of their
autograd nodes, which run their OpenMP loops inside the node).

Run (a quiet machine: pause other jobs): ``.venv/bin/python bench/step_profile.py --results results/d346-chair
--config config/davis346.yaml --runs 3dgs edi-3dgs eigs+ --gaussians 6500 [--threads 2] [--repeats 10]
[--out DIR]``.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Iterable
from pathlib import Path

import torch
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench._report import add_out_argument, table, write_section  # noqa: E402
from bench.train import method_breakdown, resized_cloud  # noqa: E402
from eigs.train.config import TrainConfig  # noqa: E402
from eigs.train.data import load_train_data  # noqa: E402
from eigs.train.gaussian.trainer import Trainer  # noqa: E402
from eigs.util.memory import keep_freed_memory  # noqa: E402

RASTER_NODE = "RasterizeToPixels"  # the rasterizer's autograd Function (src/eigs/render/csrc/autograd.cpp)
PROJECT_NODE = "ProjectGaussians"


def node_ms(events: Iterable[tuple[str, float]], node: str, steps: int) -> float:
    """Milliseconds per step of the autograd nodes whose profiler key names ``node``: ``events`` are (key, self
    CPU µs) pairs over ``steps`` steps. The forward of a C++ autograd Function does not appear under its name,
    so this is the backward node's time."""
    if steps < 1:
        raise ValueError(f"steps must be ≥ 1, got {steps}")
    return sum(us for key, us in events if node in key) / steps / 1e3


def split_backward(backward_ms: float, raster_ms: float, project_ms: float) -> float:
    """The backward's rest (ADE network, losses, trajectories, parameter activations) in ms, never negative
    (the profiled nodes and the timed backward come from different steps; a rest under 0 is clipped)."""
    return max(0.0, backward_ms - raster_ms - project_ms)


def profile_run(data, run: dict, repeats: int) -> dict[str, float]:  # noqa: ANN001
    """One run's step: ``method_breakdown``'s wall split plus the profiled rasterizer and projection backward."""
    from torch.profiler import ProfilerActivity, profile

    opts = run.get("options", {})
    cfg = TrainConfig.from_dict({"method": run["method"], "densify": False,
                                 "method_options": opts.get("method_options", {})})  # fmt: skip
    tr = Trainer(data, cfg, torch.device("cpu"))
    tr.warm_up()
    res = method_breakdown(tr, repeats)
    with profile(activities=[ProfilerActivity.CPU]) as prof:
        for _ in range(repeats):
            tr.train_step()
    events = [(e.key, float(e.self_cpu_time_total)) for e in prof.key_averages()]
    res["raster bwd"] = node_ms(events, RASTER_NODE, repeats)
    res["project bwd"] = node_ms(events, PROJECT_NODE, repeats)
    res["rest bwd"] = split_backward(res["backward"], res["raster bwd"], res["project bwd"])
    res["gaussians"] = float(len(tr.model.params["means"]))
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--results", default="results/d346-chair", help="a scene's results folder (scene.h5, b4/…)")
    ap.add_argument("--config", default="config/davis346.yaml", help="the config whose `runs:` name the runs")
    ap.add_argument("--runs", nargs="+", default=["3dgs", "edi-3dgs", "eigs+"])
    ap.add_argument("--gaussians", type=int, default=6500, help="init cloud resampled to this many Gaussians")
    ap.add_argument("--bins", type=int, default=4)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=10)
    add_out_argument(ap)
    args = ap.parse_args()
    keep_freed_memory()  # as `eigs train` does
    torch.set_num_threads(args.threads)
    runs = yaml.safe_load(Path(args.config).read_text())["runs"]
    missing = [r for r in args.runs if r not in runs]
    if missing:
        raise SystemExit(f"{args.config}: no run(s) {', '.join(missing)} under `runs:`")
    r = Path(args.results)
    b = r / f"b{args.bins}"
    data = load_train_data(r / "scene.h5", b / "edi.h5", b / "sfm", b / "init.ply")
    data.init = resized_cloud(data.init, args.gaussians)
    rows, measured = [], {}
    for name in args.runs:
        m = profile_run(data, runs[name], args.repeats)
        measured[name] = m
        raster = m["renders fwd"] + m["raster bwd"]
        ade = "" if math.isnan(m["ADE fwd+bwd"]) else f"{m['ADE fwd+bwd']:.1f}"
        rows.append([f"`{name}`", f"{m['renders']:.0f}", f"{m['renders fwd']:.1f}", f"{m['raster bwd']:.1f}",
                     f"{m['project bwd']:.1f}", f"{m['rest bwd']:.1f}", f"{m['other fwd']:.1f}", f"{m['adam']:.1f}",
                     f"{m['whole step']:.1f}", ade, f"{100 * raster / m['whole step']:.0f} %"])  # fmt: skip
        print(rows[-1], flush=True)
    cols = ["run", "renders", "renders fwd", "raster bwd", "project bwd", "rest of bwd", "other fwd", "Adam",
            "whole step", "ADE fwd+bwd", "rasterizer share"]  # fmt: skip
    body = (
        f"One training step at the scene's own size (`{r.name}`, {data.width}×{data.height}, its init cloud resampled "
        f"to {args.gaussians:,} Gaussians, no densification), {args.threads} threads, median of {args.repeats} steps "
        "(ms; `bench/step_profile.py`). `renders fwd`: every rasterizer call's forward; `raster bwd` and `project "
        "bwd`: the self time of the rasterizer's and the projection's autograd nodes (torch.profiler); `rest of bwd`: "
        "the backward's remainder (ADE network, losses, trajectories); `other fwd`: the forward outside the renders; "
        "`ADE fwd+bwd`: the ADE network alone on all Gaussians; `rasterizer share`: (renders fwd + raster bwd) over "
        "the whole step.\n\n" + table(cols, rows) + "\n"
    )
    write_section("step-profile", f"Where the step goes at {data.width}×{data.height} (issue 32)", body,
                  data={"scene": r.name, "threads": args.threads, "runs": measured}, out=args.out)  # fmt: skip
    print(body)


if __name__ == "__main__":
    main()
