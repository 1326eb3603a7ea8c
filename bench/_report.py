"""Write one benchmark's section into docs/benchmarks.md, leaving the other sections alone.

Each benchmark script owns the text between ``<!-- begin:NAME -->`` and ``<!-- end:NAME -->``;
this helper replaces it (or appends it) and stamps the machine and the date.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import math
import os
import platform
import re
import subprocess
import sys
import time
from pathlib import Path

DOC = Path(__file__).resolve().parents[1] / "docs" / "benchmarks.md"
HEADER = (
    "# Benchmarks\n\n"
    "Written by the scripts in `bench/` (never run by CI). Each section names the machine and the date it was\n"
    "measured; compare ratios measured in one run, since absolute times on shared machines drift.\n"
)


def machine() -> str:
    """One line describing this machine: CPU model, cores, Python, torch."""
    cpu = platform.processor() or "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        import torch

        n = torch.get_num_threads()
        tv = f", torch {torch.__version__} ({n} thread{'s' if n != 1 else ''})"
    except ImportError:
        tv = ""
    return f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}{tv}"


def timed(cmd: list[str], log: Path) -> float:
    """Wall seconds of ``cmd`` (its output to ``log``); a failure stops the script with the log's tail. A command
    installed beside the running interpreter (``eigs`` in .venv/bin) is taken from there, so that a script run as
    ``.venv/bin/python bench/….py`` needs no activated environment."""
    beside = Path(sys.executable).parent / cmd[0]
    if os.sep not in cmd[0] and beside.is_file():
        cmd = [str(beside), *cmd[1:]]
    t = time.perf_counter()
    with log.open("w") as f:
        proc = subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT, check=False)
    if proc.returncode != 0:
        script = Path(sys.argv[0]).name
        raise SystemExit(f"{script}: {' '.join(cmd[:3])} failed ({log}):\n{log.read_text()[-2000:]}")
    return time.perf_counter() - t


def add_out_argument(ap: argparse.ArgumentParser) -> None:
    """The ``--out DIR`` option of every bench script (the workflow's `bench` target passes results/bench)."""
    ap.add_argument(
        "--out",
        type=Path,
        default=None,
        help="write the section to DIR/NAME.md and its measurements to DIR/NAME.json instead of docs/benchmarks.md "
        "(the workflow's `bench` target; bench/report.py assembles them)",
    )


def results_roots(ap: argparse.ArgumentParser) -> tuple[argparse.Namespace, list[Path]]:
    """Parse ``--results DIR ...`` (results folders or suite ledgers holding ``<scene>/b4/eval/<run>/metrics.json``;
    default ``results``) and ``--out``; returns the arguments and the folders that hold the scenes (a ledger's
    ``results/``)."""
    ap.add_argument("--results", type=Path, nargs="+", default=[Path("results")],
                    help="results folders or suite ledgers holding <scene>/b4/eval/<run>/metrics.json")  # fmt: skip
    add_out_argument(ap)
    args = ap.parse_args()
    return args, [r / "results" if (r / "results").is_dir() else r for r in args.results]


def _atomic_write(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def write_section(name: str, title: str, body: str, data: object = None, out: Path | None = None) -> None:
    """Replace section ``name`` of docs/benchmarks.md with ``body`` (Markdown), stamped with machine and date.

    With ``out`` (a folder), write the stamped section to ``out/NAME.md`` and ``data`` (the measurements, any
    JSON-serialisable value; ``null`` when not given) to ``out/NAME.json`` instead, leaving docs/benchmarks.md alone.
    """
    stamp = f"_Measured {_dt.date.today().isoformat()} on {machine()}._"
    block = f"<!-- begin:{name} -->\n## {title}\n\n{stamp}\n\n{body.strip()}\n<!-- end:{name} -->"
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        meta = {"section": name, "title": title, "date": _dt.date.today().isoformat(), "machine": machine(),
                "load_average": list(os.getloadavg()), "data": data}  # fmt: skip
        _atomic_write(out / f"{name}.json", json.dumps(meta, indent=1, default=float) + "\n")
        _atomic_write(out / f"{name}.md", block + "\n")
        return
    text = DOC.read_text() if DOC.exists() else HEADER
    pattern = re.compile(rf"<!-- begin:{re.escape(name)} -->.*?<!-- end:{re.escape(name)} -->", re.S)
    if pattern.search(text):
        text = pattern.sub(lambda _m: block, text)
    else:
        text = text.rstrip() + "\n\n" + block + "\n"
    tmp = DOC.with_suffix(".md.tmp")
    tmp.write_text(text)
    os.replace(tmp, DOC)


def fixed(v: float, digits: int = 2, sign: bool = False) -> str:
    """``v`` with ``digits`` decimals (``sign``: always signed); "–" where it is not finite (not measured)."""
    if not math.isfinite(v):
        return "–"
    return f"{v:+.{digits}f}" if sign else f"{v:.{digits}f}"


def table(headers: list[str], rows: list[list[object]]) -> str:
    """A Markdown table; floats are printed with 4 significant digits."""

    def fmt(v: object) -> str:
        return f"{v:.4g}" if isinstance(v, float) else str(v)

    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    lines += ["| " + " | ".join(fmt(v) for v in row) + " |" for row in rows]
    return "\n".join(lines)
