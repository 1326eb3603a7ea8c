"""Per-step cost of Gaussian training, broken down, and how it grows with Gaussians and image size.

Writes the "train-step" section of docs/benchmarks.md. Needs a built-in scene's artifacts (default
``results/chair``: run ``snakemake --cores 2 all_sfm`` first, or pass ``--results DIR``).

Run: ``.venv/bin/python bench/train.py [--results results/chair] [--bins 4] [--threads 2] [--quick] [--out DIR]``
(``--quick``: 5k and 10k Gaussians, half and full image size, 8 repeats; ``--out DIR``: DIR/train-step.md,
DIR/train-step-methods.md, DIR/train-step-malloc.md and their JSON instead of docs/benchmarks.md).

The script tunes malloc as ``eigs train`` does (:mod:`eigs.util.memory`); the ``train-step-malloc`` section times
steps with and without that tuning, each in a process of its own.
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

import torch
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench._report import add_out_argument, table, write_section  # noqa: E402
from eigs.artifacts.gaussians import GaussianCloud, read_gaussian_ply  # noqa: E402
from eigs.losses import photometric_loss  # noqa: E402
from eigs.train.config import TrainConfig  # noqa: E402
from eigs.train.data import load_train_data  # noqa: E402
from eigs.train.gaussian.trainer import Trainer  # noqa: E402
from eigs.util.memory import keep_freed_memory  # noqa: E402


def resized_cloud(cloud: GaussianCloud, n: int, seed: int = 0) -> GaussianCloud:
    """``n`` Gaussians drawn (with replacement beyond the cloud's size) from ``cloud``, jittered slightly."""
    import numpy as np

    rng = np.random.default_rng(seed)
    idx = rng.choice(len(cloud), n, replace=n > len(cloud))
    jitter = rng.normal(0, 1e-3, (n, 3)).astype(np.float32)
    return GaussianCloud(cloud.means[idx] + jitter, cloud.f_dc[idx], cloud.f_rest[idx], cloud.opacity[idx],
                         cloud.log_scales[idx], cloud.quats[idx])  # fmt: skip


def breakdown(tr: Trainer, repeats: int) -> dict[str, float]:
    """Median ms of each phase of a 3dgs step: render forward, loss forward+backward, render backward, Adam,
    densification statistics."""
    m = tr.method
    names = ("render fwd", "loss fwd+bwd", "render bwd", "adam", "densify stats", "whole step")
    phases: dict[str, list[float]] = {k: [] for k in names}
    for i in range(repeats + 3):
        s = i % m.n_samples()
        t0 = time.perf_counter()
        img, _, info = tr.model.render(m.c2w[s], m.K, tr.data.width, tr.data.height, m.background, 0)
        info["means2d"].retain_grad()
        t1 = time.perf_counter()
        leaf = img.detach().requires_grad_(True)
        loss, _, _ = photometric_loss(leaf, m.images[s], tr.cfg.lambda_dssim)
        loss.backward()
        t2 = time.perf_counter()
        tr.optimizer.zero_grad(set_to_none=True)
        img.backward(leaf.grad)
        t3 = time.perf_counter()
        tr.optimizer.step()
        t4 = time.perf_counter()
        tr.strategy.after_backward(tr.model, [info])
        t5 = time.perf_counter()
        tr.train_step()
        t6 = time.perf_counter()
        if i >= 3:
            for k, a, b in (("render fwd", t0, t1), ("loss fwd+bwd", t1, t2), ("render bwd", t2, t3), ("adam", t3, t4),
                            ("densify stats", t4, t5), ("whole step", t5, t6)):  # fmt: skip
                phases[k].append((b - a) * 1e3)
    return {k: statistics.median(v) for k, v in phases.items()}


METHODS = (
    ("3dgs", {}), ("edi-3dgs", {}), ("oracle", {}), ("e2gs", {}), ("deblurring-gs", {}), ("deblurring-gs+", {}),
    ("eigs-minus", {}), ("eigs-b", {}), ("eigs", {}),
    ("eigs", {"pose_prior": True, "ade_zero_last": True, "blur_target": "discrete"}),
    ("evagaussians", {}), ("bad-gaussians", {}), ("besplat", {}),
)  # fmt: skip


def method_breakdown(tr: Trainer, repeats: int) -> dict[str, float]:
    """Median ms of one step of ``tr``'s method, split into the renders' forward (every ``model.render`` call), the
    rest of the forward (ADE, trajectories, losses), the backward (rasterizer and networks), and Adam; ``ADE
    fwd+bwd`` times the ADE network alone (all Gaussians, one view, random cotangent) when the method has one;
    ``renders``: rasterizer calls in a step (a view EDI marks sharp takes one)."""
    m, model = tr.method, tr.model
    spent, calls = [0.0], [0]
    render = model.render

    def timed_render(*a, **kw):  # noqa: ANN002, ANN003
        t = time.perf_counter()
        out = render(*a, **kw)
        spent[0] += time.perf_counter() - t
        calls[0] += 1
        return out

    model.render = timed_render
    keys = ("renders fwd", "other fwd", "backward", "adam", "whole step")
    phases: dict[str, list[float]] = {k: [] for k in keys}
    try:
        for i in range(repeats + 3):
            spent[0], calls[0] = 0.0, 0
            t0 = time.perf_counter()
            out = m.step(model, i % m.n_samples(), 0, 0)
            t1 = time.perf_counter()
            render_s, n_renders = spent[0], calls[0]
            tr.optimizer.zero_grad(set_to_none=True)
            out.loss.backward()
            t2 = time.perf_counter()
            tr.optimizer.step()
            t3 = time.perf_counter()
            tr.train_step()
            t4 = time.perf_counter()
            if i >= 3:
                for k, v in (("renders fwd", render_s), ("other fwd", t1 - t0 - render_s), ("backward", t2 - t1),
                             ("adam", t3 - t2), ("whole step", t4 - t3)):  # fmt: skip
                    phases[k].append(v * 1e3)
    finally:
        model.render = render
    res = {k: statistics.median(v) for k, v in phases.items()}
    res["renders"] = float(n_renders)
    ade = getattr(m, "ade", None)
    res["ADE fwd+bwd"] = float("nan")
    if ade is not None:
        x = model.params["means"].detach()
        ts = []
        for i in range(repeats + 3):
            t = time.perf_counter()
            y = ade(x, m.pose_inputs[0])
            y.backward(torch.randn_like(y))
            if i >= 3:
                ts.append((time.perf_counter() - t) * 1e3)
        res["ADE fwd+bwd"] = statistics.median(ts)
    return res


SUITE = Path(__file__).resolve().parents[1] / "config" / "config.yaml"  # the default suite
PLUS = yaml.safe_load(SUITE.read_text())["runs"]["eigs+"]["options"]["method_options"]  # its eigs+ run's options
MALLOC_RUNS = (("3dgs", "3dgs", {}), ("e2gs", "e2gs", {}), ("eigs+", "eigs", PLUS))
MALLOC_GAUSSIANS = 17_000  # the size the suite's multi-render runs end at (drums eigs+: 17,083 at step 1750)


def step_cost(data, spec: dict) -> dict[str, float]:  # noqa: ANN001
    """Child process: CPU ms and minor page faults per training step of ``spec`` (method, options, Gaussians,
    tuned, steps) at one thread, without densification."""
    if spec["tuned"]:
        keep_freed_memory()
    torch.set_num_threads(1)
    cloud = read_gaussian_ply(spec["cloud"]) if spec["cloud"] else data.init
    data.init = resized_cloud(cloud, spec["gaussians"])
    cfg = TrainConfig.from_dict({"method": spec["method"], "densify": False, "method_options": spec["options"]})
    tr = Trainer(data, cfg, torch.device("cpu"))
    tr.warm_up()
    for _ in range(3):
        tr.train_step()
    t, f = time.process_time(), resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(spec["steps"]):
        tr.train_step()
    n = spec["steps"]
    return {"ms": (time.process_time() - t) / n * 1e3,
            "faults": (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f) / n}  # fmt: skip


def malloc_section(args: argparse.Namespace) -> None:
    """One-thread step cost with and without :func:`keep_freed_memory`, alternating processes, 2 rounds each."""
    steps, rounds = (10, 1) if args.quick else (20, 2)
    rows, records = [], []
    for label, method, options in MALLOC_RUNS:
        res: dict[bool, list[dict[str, float]]] = {False: [], True: []}
        for _ in range(rounds):
            for tuned in (False, True):
                spec = {"method": method, "options": options, "gaussians": MALLOC_GAUSSIANS, "tuned": tuned,
                        "steps": steps, "cloud": args.cloud}  # fmt: skip
                cmd = [sys.executable, __file__, "--results", args.results, "--bins", str(args.bins),
                       "--step-cost", json.dumps(spec)]  # fmt: skip
                out = subprocess.run(cmd, capture_output=True, text=True, check=True).stdout
                res[tuned].append(json.loads(out.strip().splitlines()[-1]))
        ms = {k: min(r["ms"] for r in v) for k, v in res.items()}
        faults = {k: statistics.median(r["faults"] for r in v) for k, v in res.items()}
        rows.append([label, f"{ms[False]:.1f}", f"{ms[True]:.1f}", f"{ms[False] / ms[True]:.2f}×",
                     f"{faults[False]:,.0f}", f"{faults[True]:,.0f}"])  # fmt: skip
        records.append({"run": label, "ms_default": ms[False], "ms_tuned": ms[True], "faults_default": faults[False],
                        "faults_tuned": faults[True]})  # fmt: skip
        print(rows[-1], flush=True)
    cloud = f"resampled from `{args.cloud}`" if args.cloud else "the init cloud resampled"
    cols = ["run", "ms (glibc default)", "ms (tuned)", "speed-up", "faults (default)", "faults (tuned)"]
    md = (
        f"One training step at one thread (as the suite's jobs run), {MALLOC_GAUSSIANS:,} Gaussians, no "
        f"densification, on `{Path(args.results).name}` ({cloud}): CPU ms per step (minimum over {rounds} "
        f"process(es) of {steps} steps each) and minor page faults per step, with glibc's default malloc "
        "thresholds and with `eigs.util.memory.keep_freed_memory` (what every `eigs` command now does). Default "
        "thresholds hand a step's freed activations back to the system, so the next step faults them in again page "
        "by page.\n\n"
        + table(cols, rows) + "\n"
    )
    write_section("train-step-malloc", "Training step: malloc tuning", md, data={"runs": records}, out=args.out)
    print(md)


def size_sections(args: argparse.Namespace, r: Path, data, base: GaussianCloud) -> None:  # noqa: ANN001
    """The 3dgs step broken down by Gaussian count and by image size."""
    cfg = TrainConfig.from_dict({"method": "3dgs", "densify": False})
    rows = []
    for n in (5_000, 10_000) if args.quick else (5_000, 10_000, 20_000, 40_000):
        data.init = resized_cloud(base, n)
        tr = Trainer(data, cfg, torch.device("cpu"))
        tr.warm_up()
        b = breakdown(tr, args.repeats)
        rows.append([f"{n:,}", f"{data.width}×{data.height}"] + [f"{b[k]:.2f}" for k in b])
    # image size: the same 10k Gaussians, intrinsics scaled
    data.init = resized_cloud(base, 10_000)
    w0, h0, k0 = data.width, data.height, data.K.clone()
    size_rows = []
    for f in (0.5, 1.0) if args.quick else (0.5, 1.0, 2.0):
        data.width, data.height = int(w0 * f), int(h0 * f)
        data.K = k0.clone()
        data.K[:2] *= f
        tr = Trainer(data, cfg, torch.device("cpu"))
        tr.method.images = torch.nn.functional.interpolate(
            tr.method.images.permute(0, 3, 1, 2), size=(data.height, data.width), mode="bilinear", align_corners=False
        ).permute(0, 2, 3, 1).contiguous()
        tr.warm_up()
        b = breakdown(tr, args.repeats)
        size_rows.append(["10,000", f"{data.width}×{data.height}"] + [f"{b[k]:.2f}" for k in b])
    cols = ["Gaussians", "image", "render fwd", "loss fwd+bwd", "render bwd", "Adam", "densify stats", "whole step"]
    md = (
        f"One `3dgs` training step on `{r.name}`, {args.threads} threads, median of {args.repeats} steps (ms). "
        "The phases are timed separately (render forward, L1 + D-SSIM forward and backward, rasterizer backward, "
        "Adam over all parameters, densification statistics); `whole step` is `Trainer.train_step` "
        "(sampling, the phases, the finiteness guard).\n\n"
        "By Gaussian count (init cloud resampled):\n\n" + table(cols, rows) + "\n\nBy image size (10k Gaussians):\n\n"
        + table(cols, size_rows) + "\n"
    )
    keys = ["gaussians", "image", "render_fwd_ms", "loss_ms", "render_bwd_ms", "adam_ms", "densify_ms", "step_ms"]
    data = {"by_count": [dict(zip(keys, r, strict=True)) for r in rows],
            "by_size": [dict(zip(keys, r, strict=True)) for r in size_rows]}  # fmt: skip
    write_section("train-step", "Training step", md, data=data, out=args.out)
    print(md)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--results", default="results/chair", help="a scene's results folder (scene.h5, b4/…)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=40)
    ap.add_argument("--bins", type=int, default=4, help="the EDI artifact results/<scene>/b<B>/ to train on")
    ap.add_argument("--methods-only", action="store_true", help="only the per-method section")
    ap.add_argument("--quick", action="store_true", help="fewer Gaussian counts and sizes (see the module doc)")
    ap.add_argument("--cloud", default="", help="malloc section: a trained run's model.ply to resample from")
    ap.add_argument("--malloc-only", action="store_true", help="only the malloc section")
    ap.add_argument("--step-cost", help=argparse.SUPPRESS)  # internal: the child process of malloc_section
    add_out_argument(ap)
    args = ap.parse_args()
    if args.step_cost:
        r = Path(args.results) / f"b{args.bins}"
        data = load_train_data(Path(args.results) / "scene.h5", r / "edi.h5", r / "sfm", r / "init.ply")
        print(json.dumps(step_cost(data, json.loads(args.step_cost))))
        return
    keep_freed_memory()  # as `eigs train` does
    if not args.methods_only:
        malloc_section(args)
    if args.malloc_only:
        return
    if args.quick:
        args.repeats = min(args.repeats, 8)
    torch.set_num_threads(args.threads)
    r = Path(args.results)
    b = r / f"b{args.bins}"
    data = load_train_data(r / "scene.h5", b / "edi.h5", b / "sfm", b / "init.ply")
    base = data.init
    w0, h0, k0 = data.width, data.height, data.K.clone()
    if not args.methods_only:
        size_sections(args, r, data, base)
    # one step of every method, 10k Gaussians
    data.width, data.height, data.K = w0, h0, k0
    data.init = resized_cloud(base, 10_000)
    mrows = []
    for name, mo in METHODS:
        cfg_m = TrainConfig.from_dict({"method": name, "densify": False, "method_options": mo})
        tr = Trainer(data, cfg_m, torch.device("cpu"))
        tr.warm_up()
        b = method_breakdown(tr, max(10, args.repeats // 4))
        label = name + (" + " + ", ".join(mo) if mo else "")
        renders = b["renders fwd"]
        ade = "" if math.isnan(b["ADE fwd+bwd"]) else f"{b['ADE fwd+bwd']:.1f}"
        ratio = b["whole step"] / float(mrows[0][6]) if mrows else 1.0
        mrows.append([label, f"{b['renders']:.0f}", f"{renders:.1f}", f"{b['other fwd']:.1f}", f"{b['backward']:.1f}",
                      f"{b['adam']:.1f}", f"{b['whole step']:.1f}", ade, f"{ratio:.1f}×"])  # fmt: skip
        print(mrows[-1], flush=True)
    mcols = ["method", "renders", "renders fwd", "other fwd", "backward", "Adam", "whole step", "ADE fwd+bwd", "÷ 3dgs"]
    mmd = (
        f"One training step of every method on `{r.name}` (10,000 Gaussians, {data.width}×{data.height}, no "
        f"densification), {args.threads} threads, median of {max(10, args.repeats // 4)} steps (ms). `renders fwd`: "
        "every rasterizer call of the step; `other fwd`: the rest of the forward (ADE network, trajectories, "
        "losses); `backward`: rasterizer and network gradients; `whole step`: `Trainer.train_step`; `ADE fwd+bwd`: "
        "the ADE network alone on all Gaussians; `÷ 3dgs`: whole step over the `3dgs` step of the same run.\n\n"
        + table(mcols, mrows) + "\n"
    )
    mkeys = ["method", "renders", "renders_fwd_ms", "other_fwd_ms", "backward_ms", "adam_ms", "step_ms", "ade_ms",
             "ratio_3dgs"]  # fmt: skip
    mdata = {"scene": r.name, "threads": args.threads, "methods": [dict(zip(mkeys, x, strict=True)) for x in mrows]}
    write_section("train-step-methods", "Training step of every method", mmd, data=mdata, out=args.out)
    print(mmd)


if __name__ == "__main__":
    main()
