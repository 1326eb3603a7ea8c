"""Peak memory of ``eigs ingest --format prophesee`` on a large generated RAW file (not CI).

    .venv/bin/python bench/prophesee_memory.py [--gib 2] [--encoding evt2|evt3] [--dir /tmp]

Writes a RAW file of ``--gib`` GiB (EVT 2.0: per 64 µs one EVT_TIME_HIGH word and 15 CD events; EVT 3.0: per
4096 µs one TIME_HIGH, then per µs step a TIME_LOW, an ADDR_Y and 5 single ADDR_X events), converts it with
``eigs ingest`` in a child process and reports the child's peak resident memory (``ru_maxrss`` of
``resource.getrusage(RUSAGE_CHILDREN)``), wall time and the event count; then deletes the RAW file and the scene.
The figure goes into docs/ingestion.md by hand (with the date and the machine).
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

W, H = 1280, 720


def write_evt2(path: Path, nbytes: int) -> int:
    """EVT 2.0 file of about ``nbytes`` bytes; returns the number of CD events."""
    per = 15  # CD events per 64 µs period
    periods_per_block = 1 << 20
    rng = np.random.default_rng(0)
    n_ev = 0
    with open(path, "wb") as f:
        f.write(f"% format EVT2;height={H};width={W}\n% end\n".encode())
        written, p0 = 0, 0
        while written < nbytes:
            th = np.arange(p0, p0 + periods_per_block, dtype=np.uint32)
            words = np.empty((periods_per_block, per + 1), np.uint32)
            words[:, 0] = (np.uint32(0x8) << 28) | (th & 0x0FFFFFFF)
            lsb = np.sort(rng.integers(0, 64, (periods_per_block, per), dtype=np.uint32), axis=1)
            x = rng.integers(0, W, (periods_per_block, per), dtype=np.uint32)
            y = rng.integers(0, H, (periods_per_block, per), dtype=np.uint32)
            pol = rng.integers(0, 2, (periods_per_block, per), dtype=np.uint32)
            words[:, 1:] = (pol << 28) | (lsb << 22) | (x << 11) | y
            f.write(words.tobytes())
            written += words.nbytes
            n_ev += periods_per_block * per
            p0 += periods_per_block
    return n_ev


def write_evt3(path: Path, nbytes: int) -> int:
    """EVT 3.0 file of about ``nbytes`` bytes; returns the number of CD events."""
    per = 5  # events per µs
    steps = 4096  # µs per TIME_HIGH
    rng = np.random.default_rng(0)
    n_ev = 0
    with open(path, "wb") as f:
        f.write(f"% format EVT3;height={H};width={W}\n% end\n".encode())
        written, hi = 0, 0
        while written < nbytes:
            block = np.empty((steps, 2 + per), np.uint16)
            block[:, 0] = (0x6 << 12) | np.arange(steps, dtype=np.uint16)
            block[:, 1] = (0x0 << 12) | rng.integers(0, H, steps, dtype=np.uint16)
            pol = rng.integers(0, 2, (steps, per), dtype=np.uint16)
            block[:, 2:] = (0x2 << 12) | (pol << 11) | rng.integers(0, W, (steps, per), dtype=np.uint16)
            head = np.asarray([(0x8 << 12) | (hi & 0xFFF)], np.uint16)
            f.write(head.tobytes() + block.tobytes())
            written += 2 + block.nbytes
            n_ev += steps * per
            hi += 1
    return n_ev


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--gib", type=float, default=2.0)
    ap.add_argument("--encoding", choices=("evt2", "evt3"), default="evt2")
    ap.add_argument("--dir", default=tempfile.gettempdir())
    args = ap.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="eigs-prophesee-", dir=args.dir))
    raw, scene = folder / "big.raw", folder / "scene.h5"
    try:
        t0 = time.perf_counter()
        n = (write_evt2 if args.encoding == "evt2" else write_evt3)(raw, int(args.gib * (1 << 30)))
        size = raw.stat().st_size
        print(f"wrote {raw} ({size / (1 << 30):.2f} GiB, {n:,} events) in {time.perf_counter() - t0:.0f} s", flush=True)
        eigs = Path(sys.executable).with_name("eigs")
        cmd = [
            str(eigs),
            "ingest",
            "--format",
            "prophesee",
            str(raw),
            "-o",
            str(scene),
            "--intrinsics",
            "1000,1000,640,360",
        ]
        env = dict(os.environ, EIGS_PROGRESS="0")
        t0 = time.perf_counter()
        res = subprocess.run(cmd, env=env, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        if res.returncode != 0:
            sys.exit(f"ingest failed: {res.stderr.strip()}")
        peak_mib = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
        print(res.stdout.strip())
        print(
            f"{args.encoding}: {size / (1 << 30):.2f} GiB RAW, {n:,} events → scene "
            f"{scene.stat().st_size / (1 << 30):.2f} GiB in {wall:.0f} s; peak RSS of eigs ingest {peak_mib:.0f} MiB"
        )
        print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}")
    finally:
        for p in (raw, scene):
            p.unlink(missing_ok=True)
        folder.rmdir()


if __name__ == "__main__":
    main()
