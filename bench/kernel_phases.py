"""Per-phase cost of the backward compositing kernel as it was before issue 46 (never run by CI).

Builds the C++ sources of git revision REV (default ``357e960``, the last commit with the three-pass backward)
several times with one phase of ``rasterize_backward`` removed, and times each variant against the whole kernel
with ``bench/kernel_phases/harness.cpp`` (interleaved round by round, 1 thread, CPU time; the scene is one of
bench/rasterizer.py's distribution, 256² with 64k Gaussians by default). Variants:

- ``overhead``: no row work at all (per tile: the cotangent loads; per (tile, Gaussian): parameters, box, slot,
  zeroing the accumulators, the lane sums and the slot write);
- ``pass 1``: plus the recomputation of alpha, the validity and T / (1 - alpha);
- ``passes 1-2``: plus the colour pass (sum (c - S) v_C, v_color, the colour behind S);
- ``all``: the whole kernel again (a check: ratio ~1);
- ``no final sums``: the whole kernel without the per-Gaussian sums over the pair slots.

The differences between consecutive variants give the phases' costs (docs/benchmarks.md, "The backward kernel:
where its time went"). Needs g++ and git. Usage: ``.venv/bin/python bench/kernel_phases.py [--rev REV]
[--size 256] [--n 64000] [--rounds 8] [--runs 2]``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT))
from bench.rasterizer import revision_csrc  # noqa: E402
from eigs.render import _backend  # noqa: E402
from eigs.util.cache import cache_dir  # noqa: E402

ROW_SKIP = "            if (kk > row_max_last[r]) continue;\n"
PASS2 = "            // pass 2 (per channel)"
PASS3 = "            // pass 3: v_alpha"
PASS3_END = "                Tr[l] = Tk[l];\n            }\n"
FINAL_SUMS = "#pragma omp for schedule(static)\n        for (int64_t g = 0; g < n; ++g) {"
KEEP_T = "            for (int l = 0; l < kTile; ++l) Tr[l] = Tk[l] + dot[l];\n"


def variants(src: str) -> dict[str, str]:
    """The phase variants of the old rasterize_bwd.cpp (raises if its structure is not the three-pass kernel's)."""
    for anchor in (ROW_SKIP, PASS2, PASS3, PASS3_END, FINAL_SUMS):
        if anchor not in src:
            raise SystemExit(f"rasterize_bwd.cpp at this revision lacks {anchor.strip()!r}: not the three-pass kernel")
    i2, i3 = src.index(PASS2), src.index(PASS3)
    j = src.index(PASS3_END, i3) + len(PASS3_END)
    return {
        "overhead": src.replace(ROW_SKIP, ROW_SKIP + "            acc[r] += S(1);\n            continue;\n"),
        "pass 1": src[:i2] + KEEP_T + src[j:],
        "passes 1-2": src[:i3] + KEEP_T + src[j:],
        "all": src,
        "no final sums": src.replace(FINAL_SUMS, "if (0)\n" + FINAL_SUMS),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rev", default="357e960")
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--n", type=int, default=64_000)
    ap.add_argument("--rounds", type=int, default=8)
    ap.add_argument("--runs", type=int, default=2, help="runs of every variant (interleaved over the variants)")
    opts = ap.parse_args()
    work = cache_dir() / "kernel_phases" / opts.rev
    csrc = work / "csrc"
    csrc.mkdir(parents=True, exist_ok=True)
    for name, data in revision_csrc(opts.rev).items():
        (csrc / name).write_bytes(data)
    cxx = os.environ.get("CXX", "g++")
    flags = [*_backend.CFLAGS, "-std=c++17", f"-I{csrc}"]

    def compile_(src: Path, obj: Path, *extra: str) -> Path:
        subprocess.run([cxx, *flags, *extra, "-c", str(src), "-o", str(obj)], check=True)
        return obj

    common = [
        compile_(csrc / "projection.cpp", work / "proj.o"),
        compile_(csrc / "rasterize_fwd.cpp", work / "fwd.o"),
        compile_(csrc / "rasterize_fwd.cpp", work / "old_fwd.o", "-Deigs=eigs_old"),
        compile_(csrc / "rasterize_bwd.cpp", work / "old_bwd.o", "-Deigs=eigs_old"),
        compile_(Path(__file__).resolve().parent / "kernel_phases" / "harness.cpp", work / "harness.o"),
    ]
    exes = {}
    for i, (name, text) in enumerate(variants((csrc / "rasterize_bwd.cpp").read_text()).items()):
        src = csrc / f"variant{i}.cpp"
        src.write_text(text)
        obj = compile_(src, work / f"variant{i}.o")
        exe = work / f"variant{i}"
        subprocess.run([cxx, *common, str(obj), *_backend.LDFLAGS, "-o", str(exe)], check=True)
        exes[name] = exe
    env = dict(os.environ, OMP_NUM_THREADS="1")
    results: dict[str, list[list[float]]] = {name: [] for name in exes}
    for _ in range(opts.runs):
        for name, exe in exes.items():
            out = subprocess.run([str(exe), str(opts.size), str(opts.n), str(opts.rounds)], check=True, env=env,
                                 capture_output=True, text=True).stdout.split()  # fmt: skip
            results[name].append([float(x) for x in out[1:]])
    print(f"{opts.size}²/{opts.n} Gaussians, revision {opts.rev}, 1 thread, CPU ns per pair-lane (minima), "
          f"variant / whole kernel (median of {opts.rounds} interleaved rounds, per run)")  # fmt: skip
    print("| variant | fwd ns | whole bwd ns | variant ns | variant / whole |")
    print("|---|---|---|---|---|")
    for name, runs in results.items():
        fwd = statistics.median(r[0] for r in runs)
        whole = statistics.median(r[1] for r in runs)
        var = statistics.median(r[2] for r in runs)
        ratio = ", ".join(f"{r[3]:.2f}" for r in runs)
        print(f"| {name} | {fwd:.3f} | {whole:.3f} | {var:.3f} | {ratio} |")


if __name__ == "__main__":
    main()
