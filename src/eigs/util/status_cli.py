"""``eigs status``: one line per running or recent job of a workflow directory (eigs.util.status reads its logs/)."""

from __future__ import annotations

import argparse
import shutil
import sys
import time
from pathlib import Path

HELP = "one line per running or recent job of a workflow directory, read from its logs/ (training step, PSNR, phase)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.epilog = (
        "Reads DIR/logs/ and DIR/benchmarks/ only (no Snakemake API), so it works beside a running `snakemake` "
        "in another terminal. A training line shows the step from the run's progress bar and the last held-out "
        "PSNR it logged (every eval_every steps); an SfM line the phase it is in; other stages their last bar or "
        "log message. The age is the time since the job last wrote to its log."
    )
    parser.add_argument("--directory", "-d", type=Path, default=Path("."), help="workflow directory (default: .)")
    parser.add_argument(
        "--watch", type=float, default=None, metavar="SECONDS", help="redraw every SECONDS until Ctrl-C"
    )
    parser.add_argument(
        "--recent", type=int, default=3, metavar="N", help="also show the N jobs that finished last (default: 3)"
    )
    parser.add_argument("--all", action="store_true", help="show every job with a log")


def run(args: argparse.Namespace) -> int:
    from eigs.errors import EigsError
    from eigs.util.status import format_status, read_jobs, select

    if not (args.directory / "logs").is_dir():
        raise EigsError(args.directory, "no logs/ here: run `eigs status` in the directory Snakemake runs in")
    while True:
        jobs = read_jobs(args.directory)
        width = shutil.get_terminal_size((120, 24)).columns
        text = format_status(jobs, jobs if args.all else select(jobs, args.recent), width)
        if args.watch is None:
            print(text)
            return 0
        if sys.stdout.isatty():
            print("\033[H\033[J", end="")
        print(time.strftime("%H:%M:%S"), text, sep="  ", flush=True)
        try:
            time.sleep(args.watch)
        except KeyboardInterrupt:
            return 0
