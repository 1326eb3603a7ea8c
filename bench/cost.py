"""How a training step's cost grows with image size, Gaussian count and threads (issue 32, part 4).

``steps``: wall seconds per training step of some configured runs on one scene's artifacts, its images (blurry,
latent, ground truth) and event counts resized to each ``--sizes`` W×H (intrinsics scaled with them; bilinear for
images, nearest for counts and masks), its init cloud resampled to each ``--gaussians`` count
(bench/train.py ``resized_cloud``), at each ``--threads`` count; no densification, no held-out evaluation; median
of ``--repeats`` steps after two warm-up steps. One JSON record per point, appended to ``-o`` as it is measured
(a run cut short keeps what it measured).

``upstream``: wall seconds of `eigs edi` (B = 4) and `eigs sfm` (COLMAP, the default suite's settings: no given
poses) on a built-in scene made at each ``--shapes`` W×H:V (width, height, training views; `eigs synth` with those
overrides, not timed, kept in ``--work`` for the next call), at ``--threads`` threads, one JSON record per shape.

``model``: fits one line ``t = a + b·P`` (P megapixels) per run and Gaussian count to the ``steps`` records of one
thread count (least squares on relative error), reports its error on the measured points and at the target size
from the smaller sizes alone, scales it to 8 and 16 threads by the step-time ratios measured on the many-core
machine (``--scaling``), and predicts a run's training time, EDI and SfM at the E²NeRF synthetic size (800×800,
100 views); writes the "cost" section of docs/benchmarks.md and docs/figures/bench_cost.png.

``measured``: a finished (or running) workflow at the target size (config/size800.yaml) against that model: each
stage's wall and CPU time and peak memory from its Snakemake benchmark; per training run the step time of every
logged interval of its ``train_log.csv`` (intervals that held a held-out evaluation left out) against the model's
step time at that interval's Gaussian count (the fitted counts' lines interpolated in log count), the Gaussian
count, and the step at which the held-out PSNR first came within 0.3 dB of its best (its plateau); EDI and SfM
against the upstream power laws. Prints the section's tables (Markdown) and writes them as JSON with ``--json``.

Run: ``.venv/bin/python bench/cost.py steps --results results/d346-chair --config config/davis346.yaml
--runs 3dgs,edi-3dgs,eigs+ --sizes 128x96,346x260 --gaussians 20000 --threads 1,2 -o cost.jsonl``;
``bench/cost.py upstream --scene chair --shapes 128x96:24,256x192:24,346x260:30,128x96:100 --work /tmp/cost
--threads 2 -o upstream.jsonl``; ``bench/cost.py model --steps cost.jsonl --scaling cost_device.jsonl
--upstream upstream.jsonl``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import statistics
import sys
import time
from pathlib import Path

import torch
import torch.nn.functional as F

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench._report import add_out_argument, machine, timed  # noqa: E402
from bench.device_batch import merged_config  # noqa: E402
from bench.train import resized_cloud  # noqa: E402
from eigs.artifacts.gaussians import read_gaussian_ply  # noqa: E402
from eigs.train.config import TrainConfig  # noqa: E402
from eigs.train.data import TrainData, load_train_data  # noqa: E402
from eigs.train.gaussian.trainer import Trainer  # noqa: E402
from eigs.util.memory import keep_freed_memory  # noqa: E402


def parse_size(text: str) -> tuple[int, int]:
    """``WxH`` → (W, H), both positive."""
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise SystemExit(f"cost.py: --sizes: {text!r} is not WxH") from None
    if w < 8 or h < 8:
        raise SystemExit(f"cost.py: --sizes: {text!r} is smaller than 8x8")
    return w, h


def _images(x: torch.Tensor, h: int, w: int) -> torch.Tensor:
    """(..., H, W, C) float images → (..., h, w, C), bilinear."""
    lead = x.shape[:-3]
    y = x.reshape(-1, *x.shape[-3:]).permute(0, 3, 1, 2)
    y = F.interpolate(y, size=(h, w), mode="bilinear", align_corners=False)
    return y.permute(0, 2, 3, 1).reshape(*lead, h, w, x.shape[-1]).contiguous()


def _nearest(a, h: int, w: int):  # noqa: ANN001, ANN202
    """(..., H, W) numpy array of counts or a mask → (..., h, w), nearest pixel."""
    import numpy as np

    rows = np.minimum((np.arange(h) + 0.5) * a.shape[-2] / h, a.shape[-2] - 1).astype(int)
    cols = np.minimum((np.arange(w) + 0.5) * a.shape[-1] / w, a.shape[-1] - 1).astype(int)
    return np.ascontiguousarray(a[..., rows[:, None], cols[None, :]])


def resized(data: TrainData, w: int, h: int) -> TrainData:
    """``data`` seen by a camera of W×H pixels: images, event counts and intrinsics scaled, no held-out views."""
    K = data.K.clone()
    K[0] *= w / data.width
    K[1] *= h / data.height
    latent = _images(data.latent, h, w)
    edi = data.edi
    edi = dataclasses.replace(
        edi, latent=latent.numpy(), cum_counts=_nearest(edi.cum_counts, h, w),
        event_mask=None if edi.event_mask is None else _nearest(edi.event_mask, h, w),
        threshold_pos_map=None if edi.threshold_pos_map is None else _nearest(edi.threshold_pos_map, h, w),
        threshold_neg_map=None if edi.threshold_neg_map is None else _nearest(edi.threshold_neg_map, h, w),
    )  # fmt: skip
    sharp = None if data.sharp_train is None else _images(data.sharp_train, h, w)
    return dataclasses.replace(data, K=K, width=w, height=h, blurry=_images(data.blurry, h, w), latent=latent,
                               edi=edi, sharp_train=sharp, held_out=None)  # fmt: skip


def step_seconds(data: TrainData, run: dict, repeats: int) -> float:
    """Median wall seconds of one training step of ``run`` (a config's runs: entry) on ``data``."""
    options = {**run.get("options", {}), "method": run["method"], "densify": False}
    for key in ("steps", "schedule_steps", "eval_every"):
        options.pop(key, None)
    tr = Trainer(data, TrainConfig.from_dict(options), torch.device("cpu"))
    tr.warm_up()
    times = []
    for i in range(repeats + 2):
        t = time.perf_counter()
        tr.train_step()
        if i >= 2:
            times.append(time.perf_counter() - t)
    return statistics.median(times)


def mean_pairs(data: TrainData, views: int = 3) -> float:
    """Mean (Gaussian, tile) pairs of ``data.init`` rendered at the reference poses of the first ``views`` training
    views (what the compositing's cost follows)."""
    from eigs.render.gaussians import render_gaussians

    c = data.init
    t = {k: torch.from_numpy(v) for k, v in (("means", c.means), ("quats", c.quats), ("scales", c.log_scales),
                                              ("opacity", c.opacity), ("dc", c.f_dc))}  # fmt: skip
    sh = t["dc"].reshape(len(c), 1, -1)
    n = []
    with torch.no_grad():
        for v in range(min(views, data.n_views)):
            *_, info = render_gaussians(t["means"], t["quats"], t["scales"], t["opacity"].reshape(-1), sh,
                                        data.c2w[v, 0], data.K, data.width, data.height)  # fmt: skip
            n.append(info["n_isects"])
    return float(statistics.mean(n)) if n else 0.0


def steps(args: argparse.Namespace) -> None:
    keep_freed_memory()  # as `eigs train` does
    config = merged_config(args.config)
    runs = [r.strip() for r in args.runs.split(",") if r.strip()]
    for r in runs:
        if r not in config.get("runs", {}):
            raise SystemExit(f"cost.py: --runs: {r!r} is not a run of {', '.join(map(str, args.config))}")
    res = Path(args.results)
    b = res / f"b{args.bins}"
    base = load_train_data(res / "scene.h5", Path(args.edi) if args.edi else b / "edi.h5", b / "sfm", b / "init.ply")
    cloud = base.init if args.init is None else read_gaussian_ply(args.init)
    counts = [int(x) for x in args.gaussians.split(",")] if args.gaussians else [len(cloud)]
    if args.init is not None and max(counts) > len(cloud):
        raise SystemExit(f"cost.py: --gaussians {max(counts):,} is more than --init {args.init} holds "
                         f"({len(cloud):,}): a trained cloud is timed on subsets of itself")  # fmt: skip
    host = machine()
    out = Path(args.out)
    for size in args.sizes.split(","):
        w, h = parse_size(size)
        data = resized(base, w, h)
        for n in counts:
            data.init = resized_cloud(cloud, n)
            pairs = mean_pairs(data)
            for threads in (int(x) for x in args.threads.split(",")):
                torch.set_num_threads(threads)
                for r in runs:
                    s = step_seconds(data, config["runs"][r], args.repeats)
                    rec = {"scene": res.name, "run": r, "method": config["runs"][r]["method"], "width": w,
                           "height": h, "views": base.n_views, "gaussians": n, "threads": threads, "step_s": s,
                           "repeats": args.repeats, "machine": host, "pairs": pairs,
                           "cloud": "init" if args.init is None else str(args.init)}  # fmt: skip
                    with out.open("a") as f:
                        f.write(json.dumps(rec) + "\n")
                    print(f"{r:10s} {w}x{h} {n:>7,} G {threads:>2} thr: {s * 1e3:8.1f} ms/step", flush=True)
        del data


BINS = 4  # EDI bins of `upstream` (B + 1 latent frames per view), as the suite's first B


def parse_shape(text: str) -> tuple[int, int, int]:
    """``WxH:V`` → (W, H, V)."""
    size, sep, views = text.partition(":")
    if not sep or not views.isdigit() or int(views) < 2:
        raise SystemExit(f"cost.py: --shapes: {text!r} is not WxH:V (V >= 2 training views)")
    w, h = parse_size(size)
    return w, h, int(views)


def upstream(args: argparse.Namespace) -> None:
    eigs = [sys.executable, "-m", "eigs.cli"]
    work = Path(args.work)
    host = machine()
    for text in args.shapes.split(","):
        w, h, v = parse_shape(text)
        d = work / f"{args.scene}_{w}x{h}_v{v}"
        d.mkdir(parents=True, exist_ok=True)
        scene = d / "scene.h5"
        if not scene.is_file():
            overrides = json.dumps({"width": w, "height": h, "n_train": v})
            timed([*eigs, "synth", "--scene", args.scene, "--config", overrides, "-o", str(scene), "--threads",
                   str(args.threads)], d / "synth.log")  # fmt: skip
        b = d / f"b{BINS}"
        edi = b / "edi.h5"
        t_edi = timed([*eigs, "edi", str(scene), "-o", str(edi), "--latent-dir", str(b / "latent"), "--bins",
                       str(BINS), "--threads", str(args.threads)], d / "edi.log")  # fmt: skip
        sfm = b / "sfm"
        t_sfm = timed([*eigs, "sfm", str(scene), str(edi), "--latent-dir", str(b / "latent"), "-o", str(sfm),
                       "--config", '{"allow_given":false}', "--threads", str(args.threads)], d / "sfm.log")  # fmt: skip
        rep = json.loads((sfm / "report.json").read_text())
        rec = {"scene": args.scene, "width": w, "height": h, "views": v, "frames": v * (BINS + 1), "edi_s": t_edi,
               "sfm_s": t_sfm, "registered": rep["registration"]["fraction"], "matcher": rep.get("matcher"),
               "ate_percent": rep["accuracy"].get("ate_percent_of_extent"), "sfm_timings_s": rep.get("timings_s"),
               "threads": args.threads, "machine": host}  # fmt: skip
        with Path(args.out).open("a") as f:
            f.write(json.dumps(rec) + "\n")
        line = f"{w}x{h}, {v} views: EDI {t_edi:.1f} s, SfM {t_sfm:.1f} s, registered {rec['registered']:.0%}"
        print(line, flush=True)


def read_jsonl(path: Path) -> list[dict]:
    return [json.loads(line) for line in Path(path).read_text().splitlines() if line.strip()]


def fit_linear(P, t):  # noqa: ANN001, ANN201, N803
    """``t = a + b·P`` by least squares on relative error: (a, b)."""
    import numpy as np

    P, t = np.asarray(P, float), np.asarray(t, float)  # noqa: N806
    A = np.stack([np.ones_like(P), P], axis=1) / t[:, None]  # noqa: N806
    (a, b), *_ = np.linalg.lstsq(A, np.ones_like(t), rcond=None)
    return float(a), float(b)


def power_law(x, y):  # noqa: ANN001, ANN201
    """``y = k·x^α`` fitted in log-log: (k, α)."""
    import numpy as np

    alpha, logk = np.polyfit(np.log(x), np.log(y), 1)
    return float(np.exp(logk)), float(alpha)


def thread_ratios(d: list[dict], threads: int, target_p: float) -> dict[int, float]:
    """Step-time ratios t(``threads``) / t(T) for T = 8, 16 from one run's many-core records: ``threads``→4 at
    the largest size below ``target_p`` that has both, times 4→T at the target size (where it measured)."""
    out = {threads: 1.0}
    by = {(r["width"] * r["height"] / 1e6, r["threads"]): r["step_s"] for r in d}
    small = sorted({p for p, t in by if p < target_p and (p, threads) in by and (p, 4) in by})
    big = sorted({p for p, t in by if p >= target_p and (p, 4) in by})
    if not small or not big:
        return out
    r_small = by[small[-1], threads] / by[small[-1], 4]
    for t_to in (8, 16):
        if (big[0], t_to) in by:
            out[t_to] = r_small * by[big[0], 4] / by[big[0], t_to]
    return out


def step_at(lines: dict[int, tuple[float, float]], gaussians: float, p: float) -> float:
    """The model's step seconds at ``gaussians`` and ``p`` megapixels: ``lines`` {count: (a, b)} (t = a + b·P),
    interpolated linearly in log count between the two fitted counts around it, the nearest line's outside them."""
    import numpy as np

    counts = sorted(lines)
    t = [lines[c][0] + lines[c][1] * p for c in counts]
    return float(np.interp(np.log(max(gaussians, 1.0)), np.log(counts), t))


def plateau_step(rows: list[dict], tolerance_db: float = 0.3) -> tuple[int, float] | None:
    """(step, PSNR) where the held-out PSNR of ``train_log.csv`` rows first came within ``tolerance_db`` of its
    best; None without evaluations."""
    curve = [(int(r["step"]), float(r["psnr_novel"])) for r in rows if r.get("psnr_novel") not in (None, "")]
    if not curve:
        return None
    best = max(v for _, v in curve)
    return next((s, v) for s, v in curve if v >= best - tolerance_db)


def step_intervals(rows: list[dict]) -> list[tuple[int, float, int]]:
    """(steps, seconds per step, Gaussians at its start) of every logged interval of ``train_log.csv`` rows whose
    end row holds no held-out evaluation (those intervals include it)."""
    out = []
    for prev, row in zip(rows, rows[1:], strict=False):
        if row.get("psnr_novel") not in (None, ""):
            continue
        ds = int(row["step"]) - int(prev["step"])
        if ds > 0:
            out.append((ds, (float(row["wall_s"]) - float(prev["wall_s"])) / ds, int(prev["n_gaussians"])))
    return out


def _benchmark(path: Path) -> dict | None:
    import csv

    if not path.exists():
        return None
    rows = list(csv.DictReader(path.read_text().splitlines(), delimiter="\t"))
    return {"wall_s": float(rows[-1]["s"]), "cpu_s": float(rows[-1]["cpu_time"]),
            "max_rss_gb": float(rows[-1]["max_rss"]) / 1024} if rows else None  # fmt: skip


def parse_alias(text: str) -> tuple[str, str]:
    """``RUN=TIMED`` → (RUN, TIMED): the run of the workflow directory and the run of the ``steps`` records that
    model it (a longer copy of a configured run has the configured run's step)."""
    run, sep, timed = text.partition("=")
    if not sep or not run or not timed:
        raise SystemExit(f"cost.py: --alias: {text!r} is not RUN=TIMED")
    return run, timed


def measured(args: argparse.Namespace) -> None:
    import csv

    import numpy as np

    from bench._report import table

    d, scene, b = Path(args.directory), args.scene, args.bins
    cfg = merged_config([Path(c) for c in args.config])
    spec = cfg["scenes"][scene]
    over = spec.get("overrides", {})
    w, h, views = int(over["width"]), int(over["height"]), int(over["n_train"])
    p = w * h / 1e6
    recs = [r for r in read_jsonl(args.steps) if r["threads"] == args.threads]
    aliases = dict(parse_alias(a) for a in args.alias)
    up = read_jsonl(args.upstream) if args.upstream else []
    frames = views * (b + 1)
    predicted: dict[str, float] = {}
    if up:
        k_e, a_e = power_law(np.array([r["frames"] * r["width"] * r["height"] / 1e6 for r in up]),
                             [r["edi_s"] for r in up])  # fmt: skip
        k_s, a_s = power_law(np.array([r["frames"] for r in up], float), [r["sfm_s"] for r in up])
        predicted = {"edi": k_e * (frames * p) ** a_e, "sfm": k_s * frames**a_s}
    out: dict = {"scene": scene, "size": [w, h], "views": views, "stages": {}, "runs": {}}
    stage_rows = []
    for rule, name in (("synth", scene), ("edi", f"{scene}_b{b}"), ("sfm", f"{scene}_b{b}"), ("init", f"{scene}_b{b}"),
                       *((("train", f"{scene}_b{b}_{r}")) for r in args.runs),
                       *((("evaluate", f"{scene}_b{b}_{r}")) for r in args.runs)):  # fmt: skip
        m = _benchmark(d / "benchmarks" / rule / f"{name}.tsv")
        key = rule if rule in ("synth", "edi", "sfm", "init") else f"{rule} {name.rsplit('_', 1)[-1]}"
        out["stages"][key] = m
        pred = predicted.get(rule)
        stage_rows.append([key, "–" if m is None else f"{m['wall_s'] / 60:.1f}",
                           "–" if m is None else f"{m['cpu_s'] / 60:.1f}",
                           "–" if m is None else f"{m['max_rss_gb']:.1f}",
                           "–" if pred is None else f"{pred / 60:.1f}",
                           "–" if pred is None or m is None
                           else f"{100 * (pred / m['wall_s'] - 1):+.0f} %"])  # fmt: skip
    run_rows = []
    for run in args.runs:
        log = d / "results" / scene / f"b{b}" / run / "train_log.csv"
        if not log.exists():
            run_rows.append([run] + ["–"] * 8)
            continue
        rows = list(csv.DictReader(log.read_text().splitlines()))
        lines = {}
        timed = aliases.get(run, run)  # the run whose `steps` records model this one
        for g in sorted({r["gaussians"] for r in recs if r["run"] == timed}):
            rr = [r for r in recs if r["run"] == timed and r["gaussians"] == g]
            lines[g] = fit_linear([r["width"] * r["height"] / 1e6 for r in rr], [r["step_s"] for r in rr])
        iv = step_intervals(rows)
        meas = np.array([t for _, t, _ in iv])
        pred = np.array([step_at(lines, g, p) for _, _, g in iv]) if lines else np.full(len(iv), np.nan)
        ratio = float(np.median(pred / meas)) if len(iv) else float("nan")
        plateau = plateau_step(rows)
        gauss = [int(r["n_gaussians"]) for r in rows]
        steps = int(rows[-1]["step"]) if rows else 0
        model_train_s = float(sum(ds * t for (ds, _, _), t in zip(iv, pred, strict=True)) / max(sum(
            ds for ds, _, _ in iv), 1) * steps) if len(iv) else float("nan")
        out["runs"][run] = {"steps": steps, "gaussians_final": gauss[-1] if gauss else 0,
                            "gaussians_max": max(gauss) if gauss else 0,
                            "step_ms_median": float(np.median(meas) * 1e3) if len(iv) else None,
                            "model_over_measured": ratio, "plateau": plateau,
                            "model_train_s": model_train_s}  # fmt: skip
        run_rows.append([run, steps, f"{gauss[-1]:,}" if gauss else "–", f"{max(gauss):,}" if gauss else "–",
                         f"{np.median(meas) * 1e3:.0f}" if len(iv) else "–",
                         f"{np.median(pred) * 1e3:.0f}" if len(iv) else "–",
                         f"{100 * (ratio - 1):+.0f} %" if len(iv) else "–",
                         "–" if plateau is None else f"{plateau[0]} ({plateau[1]:.2f} dB)",
                         f"{model_train_s / 60:.0f}" if len(iv) else "–"])  # fmt: skip
    print(f"{scene}: {w}×{h}, {views} views, B = {b} ({frames} latent frames)\n")
    print(table(["stage", "wall min", "CPU min", "peak GB", "model min", "model error"], stage_rows))
    print()
    print(table(["run", "steps", "Gaussians (end)", "Gaussians (max)", "ms/step measured", "ms/step model",
                 "model error", "plateau step (PSNR)", "model min of training"], run_rows))  # fmt: skip
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1) + "\n")


def model(args: argparse.Namespace) -> None:
    import numpy as np

    from bench._report import table, write_section
    from eigs.train.catalog import method as catalog_method

    recs = [r for r in read_jsonl(args.steps) if r["threads"] == args.threads]
    runs = list(dict.fromkeys(r["run"] for r in recs))
    config = merged_config(args.config)
    dev = read_jsonl(args.scaling) if args.scaling else []
    target_p = args.target_width * args.target_height / 1e6
    fit_rows, pred_rows, data, notes, scatter = [], [], {"runs": {}}, [], []
    for run in runs:
        spec = (config.get("runs") or {}).get(run, {})
        method = spec.get("method", run)
        n_steps = int((spec.get("options") or {}).get("steps") or catalog_method(method).steps)
        scale = thread_ratios([r for r in dev if r["run"] == run], args.threads, target_p)
        if len(scale) == 1 and method in ("edi-3dgs", "oracle") and "3dgs" in data["runs"]:
            scale = dict(data["runs"]["3dgs"]["thread_speedup"])  # one render a step, as 3dgs
            notes.append(f"{run}: 3dgs's thread ratios (one render a step; {run} was not timed on the 16 cores)")
        data["runs"][run] = {"steps": n_steps, "thread_speedup": scale, "fits": []}
        for g in sorted({r["gaussians"] for r in recs if r["run"] == run}):
            rr = sorted((r for r in recs if r["run"] == run and r["gaussians"] == g),
                        key=lambda r: r["width"] * r["height"])  # fmt: skip
            P = np.array([r["width"] * r["height"] / 1e6 for r in rr])  # noqa: N806
            t = np.array([r["step_s"] for r in rr])
            a, b = fit_linear(P, t)
            rel = (a + b * P) / t - 1
            scatter.append((run, t, a + b * P))
            small = P < target_p  # out of sample: the target size predicted from the smaller sizes alone
            ext = "–"
            if small.sum() >= 2 and (~small).any():
                a_s, b_s = fit_linear(P[small], t[small])
                ext = f"{100 * ((a_s + b_s * P[~small][0]) / t[~small][0] - 1):+.1f} %"
            fit_rows.append([run, f"{g:,}", len(rr), f"{a * 1e3:.1f}", f"{b * 1e3:.0f}",
                             f"{100 * np.max(np.abs(rel)):.1f} %", ext])  # fmt: skip
            t_target = a + b * target_p
            row = [run, n_steps, f"{g:,}", f"{t_target * 1e3:.0f}"]
            row += [f"{n_steps * t_target / scale[c] / 60:.1f}" if c in scale else "–" for c in (args.threads, 8, 16)]
            pred_rows.append(row)
            data["runs"][run]["fits"].append({"gaussians": g, "a_ms": a * 1e3, "b_ms_per_mp": b * 1e3,
                                              "max_rel_err": float(np.max(np.abs(rel))), "target_ms": t_target * 1e3})
    sizes = sorted({(r["width"], r["height"]) for r in recs}, key=lambda s: s[0] * s[1])
    body = [
        f"Issue 32, part 4. `bench/cost.py steps` timed one training step ({args.threads} threads, no "
        f"densification, median of {recs[0].get('repeats', 'a few')} steps) of each run on "
        f"{recs[0].get('scene', 'the scene')}'s artifacts, its images and event counts resized to "
        f"{', '.join(f'{w}×{h}' for w, h in sizes)} (intrinsics scaled), "
        + (f"with a trained cloud (`{Path(cloud).name}`) cut to each Gaussian count by a random subset, so that its "
           "Gaussians keep their trained sizes. "
           if (cloud := recs[0].get("cloud", "init")) != "init"
           else "its init cloud resampled to each Gaussian count (copies of a sparse cloud pile on one another: "
                "far more (Gaussian, tile) pairs than a trained cloud of that count). ")
        + "A step renders one view, so the view count does not enter it (it enters the steps to a plateau, EDI and "
        "SfM, below). At a fixed Gaussian count the step time is linear in the pixels, `t = a + b·P` (P megapixels; "
        "least squares on relative error), and the model keeps one line per count. `800×800 from smaller`: "
        "the error of the line fitted to the smaller sizes alone, at 800×800 (an out-of-sample check).\n\n"
        + table(["run", "Gaussians", "sizes", "a (ms)", "b (ms per MP)", "max |error|", "800×800 from smaller"],
                fit_rows),  # fmt: skip
    ]
    dev_machine = dev[0]["machine"] if dev else "–"
    body.append(
        f"Training time at the E²NeRF synthetic size ({args.target_width}×{args.target_height}): the fitted step "
        f"time × the run's configured steps, on {args.threads} cores, and on 8 and 16 cores with the step-time "
        f"ratios measured on the 16-core host of the device machine ({dev_machine}): {args.threads}→4 threads at "
        "346×260 times 4→8 and 4→16 threads at 800×800 (20,000 Gaussians). The step count is the budget read from "
        "the 128×96 curves; at 346×260 eigs+ reached its plateau within it (docs/results.md); at 800×800 it is "
        "not measured. Minutes:\n\n"
        + table(["run", "steps", "Gaussians", f"ms/step ({args.threads} threads)", f"{args.threads} cores",
                 "8 cores", "16 cores"], pred_rows)  # fmt: skip
        + "".join(f"\n- {n}" for n in notes)
    )
    if args.upstream:
        up = read_jsonl(args.upstream)
        up_rows = []
        for r in up:
            ph = r.get("sfm_timings_s") or {}
            up_rows.append([f"{r['width']}×{r['height']}", r["views"], r["frames"], f"{r['edi_s']:.1f}",
                            f"{r['sfm_s']:.1f}", r.get("matcher", "–"), f"{ph.get('features', float('nan')):.1f}",
                            f"{ph.get('matching', float('nan')):.1f}", f"{ph.get('mapping', float('nan')):.1f}",
                            f"{100 * r['registered']:.0f} %",
                            "–" if r["ate_percent"] is None else f"{r['ate_percent']:.2f} %"])  # fmt: skip
        x = np.array([r["frames"] * r["width"] * r["height"] / 1e6 for r in up])  # frame-megapixels
        k_e, a_e = power_law(x, [r["edi_s"] for r in up])
        n = np.array([r["frames"] for r in up], float)
        k_s, a_s = power_law(n, [r["sfm_s"] for r in up])
        timed_up = [r for r in up if r.get("sfm_timings_s")]
        by_size = sorted(timed_up, key=lambda r: (r["width"] * r["height"], r["views"]))
        features = ", ".join(f"{r['sfm_timings_s']['features']:.1f} s at {r['width']}×{r['height']}"
                             for r in (by_size[0], by_size[-1]))  # fmt: skip
        n_t = args.target_views * (BINS + 1)
        x_t = n_t * target_p
        body.append(
            f"EDI (B = 4, the suite's estimated mode) and COLMAP SfM (the default suite's settings; `auto` matcher: "
            f"exhaustive up to 150 latent frames, sequential beyond) of `chair` made at each size and view count, "
            f"{up[0]['threads']} threads ({up[0]['machine']}); SfM phases in seconds:\n\n"
            + table(["image", "views", "frames", "EDI s", "SfM s", "matcher", "features", "matching", "mapping",
                     "registered", "ATE"], up_rows)  # fmt: skip
            + f"\n\nEDI ≈ {k_e:.3g}·(frame-megapixels)^{a_e:.2f} s and SfM ≈ {k_s:.3g}·frames^{a_s:.2f} s (power "
            f"laws through these points; incremental mapping, not matching, dominates at 500 frames). At "
            f"{args.target_width}×{args.target_height} with {args.target_views} views ({n_t} latent frames): EDI "
            f"~{k_e * x_t ** a_e / 60:.0f} min, SfM ~{k_s * n_t ** a_s / 60:.0f} min from the frame count alone; the "
            f"features per image grow with the image size (features {features}), so at "
            f"{args.target_width}×{args.target_height} SfM will take longer than that."
        )
        data["upstream"] = {"edi_power": [k_e, a_e], "sfm_power": [k_s, a_s]}
    fig = (Path(args.out) if args.out else Path(__file__).resolve().parents[1] / "docs" / "figures") / "bench_cost.png"
    fig.parent.mkdir(parents=True, exist_ok=True)
    _scatter_figure(fig, scatter)
    body.append("![measured against fitted step time](figures/bench_cost.png)")
    write_section("cost", "How the cost grows (issue 32)", "\n\n".join(body), data=data, out=args.out)


def _scatter_figure(fig: Path, scatter: list) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    f, ax = plt.subplots(figsize=(4.5, 4))
    lo = min(float(m.min()) for _, m, _ in scatter) * 1e3 / 1.5
    hi = max(float(m.max()) for _, m, _ in scatter) * 1e3 * 1.5
    colours: dict[str, str] = {}
    for run, meas, pred in scatter:
        first = run not in colours
        colours.setdefault(run, f"C{len(colours)}")
        ax.loglog(meas * 1e3, pred * 1e3, "o", color=colours[run], label=run if first else None, alpha=0.8)
    ax.plot([lo, hi], [lo, hi], "k--", lw=0.8)
    ax.set_xlabel("measured ms / step")
    ax.set_ylabel("fitted ms / step")
    ax.legend()
    f.tight_layout()
    tmp = fig.with_name(fig.name + ".tmp.png")
    f.savefig(tmp, dpi=110)
    plt.close(f)
    os.replace(tmp, fig)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("steps", help="time training steps over sizes, Gaussian counts and threads")
    s.add_argument("--results", required=True, help="a scene's results folder (scene.h5, b<B>/edi.h5, sfm, init.ply)")
    s.add_argument("--bins", type=int, default=4)
    s.add_argument("--edi", help="the EDI file, when it is not <results>/b<B>/edi.h5")
    s.add_argument("--config", type=Path, nargs="+", required=True, help="config files with the runs")
    s.add_argument("--runs", required=True, help="comma-separated run names of the config")
    s.add_argument("--sizes", required=True, help="comma-separated WxH")
    s.add_argument("--gaussians", default="20000",
                   help="comma-separated Gaussian counts ('' with --init: the cloud's own count)")
    s.add_argument("--init", type=Path, help="time this cloud (a trained model.ply) instead of the scene's init cloud: "
                   "each count a random subset of it, so that its Gaussians keep their trained sizes")
    s.add_argument("--threads", default="1", help="comma-separated thread counts")
    s.add_argument("--repeats", type=int, default=5)
    s.add_argument("-o", "--out", required=True, help="JSON-lines file the records are appended to")
    u = sub.add_parser("upstream", help="time EDI and SfM over image sizes and view counts")
    u.add_argument("--scene", default="chair", help="built-in scene")
    u.add_argument("--shapes", required=True, help="comma-separated WxH:V")
    u.add_argument("--work", required=True, help="folder for the scenes (kept: a second call skips synth)")
    u.add_argument("--threads", type=int, default=2)
    u.add_argument("-o", "--out", required=True, help="JSON-lines file the records are appended to")
    m = sub.add_parser("model", help="fit the step-cost model, predict the E²NeRF synthetic size, write the section")
    m.add_argument("--steps", type=Path, required=True, help="records of `steps` on this machine")
    m.add_argument("--threads", type=int, default=2, help="the thread count of those records to fit")
    m.add_argument("--scaling", type=Path, help="records of `steps` on a many-core machine (thread counts)")
    m.add_argument("--upstream", type=Path, help="records of `upstream`")
    m.add_argument("--config", type=Path, nargs="+", default=[Path("config/config.yaml")], help="the runs' budgets")
    m.add_argument("--target-width", type=int, default=800)
    m.add_argument("--target-height", type=int, default=800)
    m.add_argument("--target-views", type=int, default=100)
    add_out_argument(m)
    x = sub.add_parser("measured", help="a workflow run at the target size against the model")
    x.add_argument("--directory", required=True, help="the workflow directory of the run (results/, benchmarks/)")
    x.add_argument("--config", nargs="+", default=["config/size800.yaml"], help="its config file(s)")
    x.add_argument("--scene", default="chair800")
    x.add_argument("--bins", type=int, default=4)
    x.add_argument("--runs", nargs="+", default=["edi-3dgs", "eigs+"])
    x.add_argument("--steps", type=Path, required=True, help="records of `steps` (the model's step times)")
    x.add_argument("--threads", type=int, default=2)
    x.add_argument("--upstream", type=Path, help="records of `upstream` (EDI and SfM)")
    x.add_argument("--json", type=Path, help="also write the measurements as JSON here")
    x.add_argument("--alias", action="append", default=[], metavar="RUN=TIMED",
                   help="model RUN with the `steps` records of TIMED (e.g. eigs+plateau=eigs+)")
    a = ap.parse_args(argv)
    {"steps": steps, "upstream": upstream, "model": model, "measured": measured}[a.cmd](a)


if __name__ == "__main__":
    main()
