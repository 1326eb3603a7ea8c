"""Generate the six default synthetic scenes; report time per scene, blur extent and event counts.

Writes the "synth" section of docs/benchmarks.md. Run: ``.venv/bin/python bench/synth.py [--threads 2]
[--keep DIR] [--out DIR] [scene ...]`` (scene files go to a temporary directory unless ``--keep`` is given;
``--out DIR``: DIR/synth.md and DIR/synth.json instead of docs/benchmarks.md).

Blur extent: every scene point seen at a pixel centre at the start of an exposure is projected at 17 times along
the true trajectory of that exposure; its extent is the diameter of those projections (px). The table gives the
median and 90th percentile over all points of all 24 training views (128 px width).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench._report import add_out_argument, table, write_section  # noqa: E402

DEFAULT_SCENES = ["blocks", "chair", "tree", "dish", "spheres", "drums"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("scenes", nargs="*", default=DEFAULT_SCENES)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--keep", help="keep the scene files and contact sheets in this directory")
    add_out_argument(ap)
    args = ap.parse_args()
    os.environ.setdefault("EIGS_PROGRESS", "0")
    from eigs.synth.generate import generate, write_generated
    from eigs.util.threads import set_threads

    set_threads(args.threads)
    rows = []
    total = 0.0
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(args.keep or tmp)
        out.mkdir(parents=True, exist_ok=True)
        for name in args.scenes:
            t0 = time.perf_counter()
            g = generate(name, show_progress=False, threads=args.threads)
            write_generated(g, out / f"{name}.h5", contact_sheet=out / f"{name}_contact_sheet.png")
            dt = time.perf_counter() - t0
            total += dt
            st = g.stats
            size_mb = (out / f"{name}.h5").stat().st_size / 1e6
            rows.append([
                name, round(dt, 1), round(st["render_seconds"], 1), round(st["simulate_seconds"], 1),
                st["frames_rendered"], round(st["blur_median_px"], 1), round(st["blur_p90_px"], 1),
                f"{st['events'] / 1e6:.2f} M", f"{st['events_in_exposures'] / 1e6:.2f} M",
                f"{st['exposure_crossings_p99']} / {st['exposure_crossings_p999']} / {st['exposure_crossings_max']}",
                round(size_mb, 1),
            ])
            print(name, rows[-1], flush=True)
    body = (
        f"`bench/synth.py` with {args.threads} threads: default parameters (128×96, 24 training + 12 novel views, "
        "80 sub-frames per 100 ms exposure, 2×2 supersampling), scene file + contact sheet written.\n"
        "Blur extent: diameter (px) of each visible scene point's projections along the true trajectory of its "
        "exposure; median and 90th percentile over all points of all views. Crossings: threshold crossings per "
        "active pixel per sub-frame step inside exposures (99th / 99.9th percentile / max).\n\n"
        + table(
            ["scene", "total s", "render s", "events s", "frames", "blur median px", "blur p90 px", "events",
             "in exposures", "crossings/step", "file MB"],
            rows,
        )
        + f"\n\nAll {len(rows)} scenes: {total:.0f} s (1-min load average {load0:.1f} at the start, "
        f"{os.getloadavg()[0]:.1f} at the end, on {os.cpu_count()} cores: the machine is shared)."
    )
    keys = ["scene", "total_s", "render_s", "events_s", "frames", "blur_median_px", "blur_p90_px"]
    data = [dict(zip(keys, r[: len(keys)], strict=True)) for r in rows]
    write_section("synth", "Synthetic scenes (eigs synth)", body, data=data, out=args.out)


if __name__ == "__main__":
    main()
