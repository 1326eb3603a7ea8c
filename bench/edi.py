"""EDI benchmark: run time versus error over B ∈ {2, 4, 8, 16} and both modes on the six built-in scenes, threshold
estimates against the simulator's C, and throughput (latent megapixels/s, binning events/s).

    .venv/bin/python bench/edi.py [--work DIR] [--scenes blocks,chair,...] [--bins 2,4,8,16] [--threads 1] [--out DIR]

Scenes are generated once into ``--work`` (default /tmp/eigs-bench-edi) with ``eigs synth``: the defaults (noisy
sensor: σ = 0.03 mismatch, shot and leak noise, refractory period) and a clean variant (σ = 0, no noise, no
refractory period, linear response). Ground-truth sharp frames at every latent time are rendered with the
generator's own camera path and ray caster (checked against the scene's stored sharp frames at latent time 0).
Writes the ``edi`` section of docs/benchmarks.md (``--out DIR``: DIR/edi.md and DIR/edi.json instead).
"""

from __future__ import annotations

import argparse
import inspect
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench._report import add_out_argument, table, write_section  # noqa: E402

SCENES = ["blocks", "chair", "tree", "dish", "spheres", "drums"]
CLEAN = {"threshold_sigma": 0, "shot_noise_hz": 0, "leak_rate_hz": 0, "refractory_us": 0, "camera_response": "linear"}


def ensure_scene(work: Path, name: str, clean: bool, threads: int) -> Path:
    import json

    out = work / f"{name}{'_clean' if clean else ''}.h5"
    if not out.exists():
        cmd = [str(Path(sys.executable).parent / "eigs"), "synth", "--scene", name, "-o", str(out),
               "--threads", str(threads)]
        if clean:
            cmd += ["--overrides", json.dumps(CLEAN)]
        print("generating", out, flush=True)
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return out


def sharp_at(name: str, overrides: dict | None, times: np.ndarray, threads: int) -> np.ndarray:
    """(N, H, W, 3) uint8 ground-truth sharp frames of built-in scene ``name`` at ``times`` (µs), rendered exactly
    as the generator renders its sharp frames (same path, caster and encoding)."""
    from eigs.synth import generate as g
    from eigs.synth.raycast import RayCaster
    from eigs.synth.scenes import get_spec, resolve_params

    spec = get_spec(name)
    p = resolve_params(name, ("overrides", overrides))
    K = g.intrinsics(p["width"], p["height"], p["fov_deg"])
    kw = {"background": spec.background, "lighting": spec.lighting, "texture_size": p["texture_size"]}
    if "pixel_footprint" in inspect.signature(RayCaster.__init__).parameters:  # older generator versions
        kw["pixel_footprint"] = p["orbit_radius"] / K[0, 0]
    caster = RayCaster(spec.build(), **kw)
    root = np.random.default_rng(p["seed"])
    rng_shake, _ = (np.random.default_rng(s) for s in root.bit_generator.seed_seq.spawn(2))
    path, _ = g.build_path(p, spec, rng_shake)
    out = []
    for chunk in np.array_split(times, max(1, len(times) // 64)):
        rgb = caster.render(path(chunk), K, p["width"], p["height"], supersample=p["supersample"],
                            threads=threads).rgb
        out.append(g.encode(rgb, p["camera_response"]))
    return np.concatenate(out)


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    return float(10 * np.log10(1.0 / max(np.mean((a.astype(np.float64) - b) ** 2), 1e-20)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--work", default="/tmp/eigs-bench-edi")
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--bins", default="2,4,8,16")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--no-write", action="store_true", help="print only, leave docs/benchmarks.md alone")
    add_out_argument(ap)
    args = ap.parse_args()

    import os

    os.environ.setdefault("EIGS_PROGRESS", "0")
    from eigs.edi.binning import bin_events, latent_times
    from eigs.edi.edi import ExposureIntegral, edi_continuous, edi_e2nerf, to_linear
    from eigs.edi.pipeline import EdiOptions, compute_edi
    from eigs.scene import read_scene
    from eigs.util.threads import set_threads

    set_threads(args.threads)
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    scenes = [s for s in args.scenes.split(",") if s]
    bins_list = [int(b) for b in args.bins.split(",")]

    rows_rt: dict[tuple[int, str], list] = {}
    thr_rows = []
    thr_err_clean, thr_err_noisy = [], []
    gains_b4 = []
    sizes: set[str] = set()
    binning_rates, latent_rates_est, latent_rates_e2 = [], [], []
    for name in scenes:
        noisy_p = ensure_scene(work, name, False, args.threads)
        clean_p = ensure_scene(work, name, True, args.threads)
        scene = read_scene(noisy_p)
        c_true = float(scene.contrast_threshold or 0.2)
        exp = scene.frames.exposure_us
        v_n, h, w = scene.frames.blurry.shape[:3]
        sizes.add(f"{w}×{h}, {v_n} views")
        # ground truth check at latent time 0
        gt0 = sharp_at(name, None, latent_times(exp, 4)[:2, 0], args.threads)
        idx0 = [int(np.flatnonzero((scene.sharp.kind == 0) & (scene.sharp.view == v))[0]) for v in range(2)]
        assert np.abs(gt0.astype(int) - scene.sharp.images[idx0].astype(int)).max() <= 1, "GT re-render mismatch"

        # throughput: binning all exposure events into 4 bins per view
        ev = scene.events
        lt4 = latent_times(exp, 4)
        t0 = time.perf_counter()
        n_ev = 0
        for v in range(v_n):
            a, b = ev.view_index[v]
            bin_events(ev.x[a:b], ev.y[a:b], ev.t[a:b], ev.p[a:b], lt4[v], h, w)
            n_ev += int(b - a)
        binning_rates.append(n_ev / (time.perf_counter() - t0))

        for bins in bins_list:
            lt = latent_times(exp, bins)
            gt = sharp_at(name, None, lt.reshape(-1), args.threads).reshape(v_n, bins + 1, h, w, 3) / 255.0
            blur = scene.frames.blurry / 255.0
            p_blur = np.mean([psnr(blur[v], gt[v, k]) for v in range(v_n) for k in range(bins + 1)])
            for mode in ("estimated", "e2nerf"):
                t0 = time.perf_counter()
                res = compute_edi(scene, EdiOptions(mode=mode, bins=bins, show_progress=False), str(noisy_p))
                dt = time.perf_counter() - t0
                p_lat = np.mean([psnr(res.latent[v, k], gt[v, k]) for v in range(v_n) for k in range(bins + 1)])
                rows_rt.setdefault((bins, mode), []).append((dt, p_lat, p_blur))
                if bins == 4 and mode == "estimated":
                    gains_b4.append(p_lat - p_blur)
                    c_noisy = float(res.threshold[0])
                    # latent-only throughput at the found c (threshold search excluded)
                    t1 = time.perf_counter()
                    for v in range(v_n):
                        a, b = ev.view_index[v]
                        integ = ExposureIntegral(ev.x[a:b], ev.y[a:b], ev.t[a:b], ev.p[a:b], exp[v, 0], exp[v, 1],
                                                 lt[v, 0], h, w)
                        edi_continuous(to_linear(scene.frames.blurry[v], "linear"), res.cum_counts[v],
                                       integ.log_mean_exp(c_noisy), c_noisy)
                    latent_rates_est.append(v_n * (bins + 1) * h * w / 1e6 / (time.perf_counter() - t1))
                    t1 = time.perf_counter()
                    for v in range(v_n):
                        edi_e2nerf(scene.frames.blurry[v], res.cum_counts[v])
                    latent_rates_e2.append(v_n * (bins + 1) * h * w / 1e6 / (time.perf_counter() - t1))
            print(f"{name} B={bins}: " + ", ".join(
                f"{m} {rows_rt[(bins, m)][-1][1]:.2f} dB ({rows_rt[(bins, m)][-1][0]:.1f} s)"
                for m in ("estimated", "e2nerf")) + f", blurry {p_blur:.2f} dB", flush=True)
        clean = read_scene(clean_p)
        c_clean = float(compute_edi(clean, EdiOptions(show_progress=False), str(clean_p)).threshold[0])
        thr_err_clean.append(c_clean / c_true - 1)
        thr_err_noisy.append(c_noisy / c_true - 1)
        thr_rows.append([name, c_true, round(c_clean, 4), f"{100 * (c_clean / c_true - 1):+.1f} %",
                         round(c_noisy, 4), f"{100 * (c_noisy / c_true - 1):+.1f} %"])
        print(f"{name}: C = {c_true}, clean estimate {c_clean:.4f}, noisy estimate {c_noisy:.4f}", flush=True)

    rt_rows = []
    for (bins, mode), vals in sorted(rows_rt.items()):
        arr = np.array(vals)
        rt_rows.append([bins, mode, round(float(arr[:, 0].mean()), 2), round(float(arr[:, 1].mean()), 2),
                        round(float(arr[:, 2].mean()), 2), f"{float((arr[:, 1] - arr[:, 2]).mean()):+.2f}"])
    body = (
        f"Scenes: {', '.join(scenes)} ({'; '.join(sorted(sizes))}, noisy sensor defaults unless stated), "
        f"{args.threads} thread(s). PSNR of the latent frames against ground-truth sharp frames rendered at the same "
        "latent times (all views, all k), and of the blurry frame against the same frames. Run time is the whole "
        "`compute_edi` call per scene (binning, mask, threshold search, latent frames), without file I/O.\n\n"
        "### Run time versus error\n\n"
        + table(["B", "mode", "time / scene (s)", "latent PSNR (dB)", "blurry PSNR (dB)", "gain (dB)"], rt_rows)
        + f"\n\nMean gain of the estimated mode at B = 4: **{np.mean(gains_b4):+.2f} dB** "
        "(acceptance: ≥ 3 dB).\n\n"
        "### Contrast threshold (scene scope) versus the simulator's C\n\n"
        + table(["scene", "C", "clean: estimate", "error", "noisy defaults: estimate", "error"], thr_rows)
        + f"\n\nClean variants (σ = 0, no noise, linear response): mean |error| "
        f"{100 * np.mean(np.abs(thr_err_clean)):.1f} %, max {100 * np.max(np.abs(thr_err_clean)):.1f} % "
        "(acceptance: within ±20 %). Noisy defaults: mean |error| "
        f"{100 * np.mean(np.abs(thr_err_noisy)):.1f} %, max {100 * np.max(np.abs(thr_err_noisy)):.1f} %.\n\n"
        "### Throughput\n\n"
        + table(["what", "rate"], [
            ["binning (events into 4 bins per view)", f"{np.median(binning_rates) / 1e6:.1f} M events/s"],
            ["estimated mode latent frames (exact integral + frames, given c)",
             f"{np.median(latent_rates_est):.1f} latent MP/s"],
            ["E²NeRF mode latent frames", f"{np.median(latent_rates_e2):.1f} latent MP/s"],
        ])
    )
    print(body)
    data = {
        "scenes": scenes,
        "threads": args.threads,
        "runtime_error": [{"bins": b, "mode": m, "time_s": t, "latent_psnr": p, "blurry_psnr": q}
                          for b, m, t, p, q, _g in rt_rows],
        "threshold_error_clean": [float(e) for e in thr_err_clean],
        "threshold_error_noisy": [float(e) for e in thr_err_noisy],
        "binning_events_per_s": float(np.median(binning_rates)),
    }  # fmt: skip
    if not args.no_write:
        write_section("edi", "EDI latent frames (bench/edi.py)", body, data=data, out=args.out)


if __name__ == "__main__":
    main()
