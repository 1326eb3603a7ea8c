"""Train a plateau reference: one run of the default suite continued past its budget, so that the run's stop can be
checked against the level its method reaches with more training (issue 18: no method stopped earlier than within
0.3 dB of its plateau).

The reference trains the run's method and options (``config/config.yaml`` ``runs:``) on one scene of a workflow
directory where that scene's upstream (scene file, EDI, SfM, init) has run, with more steps: by default the rest of
the run's schedule when it stops part-way through a longer one (``schedule_steps``), else twice its steps (a longer
schedule of its own: the learning rate then decays over the longer run). The run folder is written to a scratch
directory; its ``config.json`` and ``train_log.csv`` are copied to ``LEDGER/plateau/<scene>_b<B>_<run>/``, where
bench/suite_report.py compares the suite run's final held-out PSNR with the best the reference reached.

Run: ``.venv/bin/python bench/plateau_reference.py --directory WORKFLOW_DIR --scene chair --run e2nerf``
(``--steps N`` to choose the length, ``--eval-every N``, ``--threads``, ``--ledger`` default ``docs/suite``).
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
DEFAULT_LEDGER = REPO / "docs" / "suite"
KEPT = ("config.json", "train_log.csv")


def reference_dir(ledger: Path, scene: str, bins: int, run: str) -> Path:
    """Where a plateau reference of ``run`` on ``scene`` at B = ``bins`` is kept in the ledger."""
    return Path(ledger) / "plateau" / f"{scene}_b{bins}_{run}"


def reference_options(spec: dict, steps: int | None, eval_every: int | None = None) -> dict:
    """The run's `eigs train --config` values with the reference's step count (``steps`` or the default above) and,
    when given, its held-out evaluation interval."""
    options = dict(spec.get("options", {}))
    if eval_every is not None:
        options["eval_every"] = int(eval_every)
    if steps is None:
        own = int(options.get("steps", 0))
        schedule = int(options.get("schedule_steps", 0))
        if own <= 0:
            raise ValueError("the run has no `steps` option (it trains to its method's default): pass --steps")
        steps = schedule if schedule > own else 2 * own
    options["steps"] = int(steps)
    if int(options.get("schedule_steps", 0)) < steps:
        options.pop("schedule_steps", None)  # the reference runs a schedule of its own length
    return {"method": spec["method"], **options}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--directory", type=Path, required=True, help="workflow directory with the scene's upstream")
    ap.add_argument("--scene", required=True)
    ap.add_argument("--run", required=True, help="a run name of the config's `runs:`")
    ap.add_argument("--steps", type=int, default=None)
    ap.add_argument("--eval-every", type=int, default=None, help="held-out evaluation interval (default: the run's)")
    ap.add_argument("--config", type=Path, default=REPO / "config" / "config.yaml")
    ap.add_argument("--ledger", type=Path, default=DEFAULT_LEDGER)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    cfg = yaml.safe_load(args.config.read_text())
    if args.run not in cfg.get("runs", {}):
        raise SystemExit(f"plateau_reference.py: error: run {args.run!r} is not in {args.config}")
    spec = cfg["runs"][args.run]
    bins = int(spec.get("bins", cfg.get("edi", {}).get("bins", [4])[0]))
    try:
        values = reference_options(spec, args.steps, args.eval_every)
    except ValueError as err:
        raise SystemExit(f"plateau_reference.py: error: {args.run}: {err}") from None
    d = args.directory.resolve()
    inputs = [d / "results" / args.scene / "scene.h5"] + [
        d / "results" / args.scene / f"b{bins}" / n for n in ("edi.h5", "sfm", "init.ply")
    ]
    absent = [str(p) for p in inputs if not p.exists()]
    if absent:
        raise SystemExit(f"plateau_reference.py: error: upstream not run in {d}: {', '.join(absent)}")
    eigs = Path(sys.executable).with_name("eigs")
    dest = reference_dir(args.ledger, args.scene, bins, args.run)
    with tempfile.TemporaryDirectory(prefix="plateau-") as tmp:
        run_dir = Path(tmp) / "run"
        cmd = [str(eigs), "train", *map(str, inputs), "-o", str(run_dir), "--config", json.dumps(values),
               "--threads", str(args.threads)]  # fmt: skip
        print(f"plateau_reference.py: {args.scene} {args.run}: {values['steps']} steps", flush=True)
        if subprocess.run(cmd).returncode != 0:
            raise SystemExit(f"plateau_reference.py: error: eigs train failed for {args.scene} {args.run}")
        staging = dest.with_name(dest.name + ".partial")
        shutil.rmtree(staging, ignore_errors=True)
        staging.mkdir(parents=True)
        for name in KEPT:
            shutil.copy2(run_dir / name, staging / name)
        shutil.rmtree(dest, ignore_errors=True)
        staging.rename(dest)
    print(f"plateau_reference.py: wrote {dest}")


if __name__ == "__main__":
    main()
