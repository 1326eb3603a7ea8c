"""Whole training steps of this tree against other git revisions, interleaved (issue 46, part 3).

For each revision a throwaway checkout (``git worktree``) is made under ``--work``, and its rasterizer extension built
once (it carries its own sources); then for ``--rounds`` rounds, every (revision, case) runs in a fresh child process
(one after the other, the order alternating between rounds): the child loads a scene's artifacts with that
checkout's package, resamples the init cloud to the case's Gaussian count, builds the run's trainer (no
densification), takes ``--warm`` untimed steps and times ``--steps`` more (``Trainer.train_step``, wall time, the
median). The section reports each case's median over the rounds and the ratio this tree / revision, per round
and overall; both builds run on the same machine within minutes of each other, so the ratio is what to compare.

Run (a quiet machine): ``.venv/bin/python bench/step_ab.py --against 357e960 --case
results/toy:config/toy.yaml:eigs+:0 --case results/d346-chair:config/davis346.yaml:eigs+:6500 [--threads 2]
[--rounds 5] [--own-config] [--out DIR]``; a case is ``RESULTS:CONFIG:RUN:GAUSSIANS`` (0: the init cloud as it is).
The run's options come from this tree's CONFIG for every revision (the same settings timed on each build), or with
``--own-config`` from each revision's own copy of CONFIG (each build with the settings it had configured, when a
change of the run's options is part of what is compared).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
OURS = "this tree"  # the name of the tree this script runs in, in the output and its records


def child(args: argparse.Namespace) -> None:
    """Time one case with the package on ``sys.path`` (the checkout under test): prints one JSON line."""
    try:  # the process set-up `eigs` does before torch loads, as far as the revision has it
        from eigs.util import memory
    except ImportError:
        memory = None
    for setup in ("keep_freed_memory", "use_huge_pages"):
        if hasattr(memory, setup):
            getattr(memory, setup)()
    import numpy as np
    import torch
    import yaml

    from eigs.artifacts.gaussians import GaussianCloud

    try:
        from eigs.plan import is_field_method
    except ImportError:  # before eigs.plan (2026-11-27): the field methods were these

        def is_field_method(method: str) -> bool:
            return method in ("nerf", "deblur-nerf", "edi-nerf", "e2nerf")

    from eigs.train.config import TrainConfig
    from eigs.train.data import load_train_data

    try:  # the trainer's module moved in 2026-11 (issue 47)
        from eigs.train.gaussian.trainer import Trainer
    except ImportError:
        from eigs.train.loop import Trainer  # type: ignore[no-redef]
    torch.set_num_threads(args.threads)
    results, config, run, gaussians = args.case[0].split(":")
    spec = yaml.safe_load(Path(config).read_text())["runs"][run]
    r = Path(results)
    b = r / f"b{spec.get('bins', 4)}"  # the run's own B (Table III's rows)
    data = load_train_data(r / "scene.h5", b / "edi.h5", b / "sfm", b / "init.ply")
    n = int(gaussians)
    if n > 0:  # the same draw as bench/train.py's resized_cloud
        c = data.init
        rng = np.random.default_rng(0)
        idx = rng.choice(len(c), n, replace=n > len(c))
        jitter = rng.normal(0, 1e-3, (n, 3)).astype(np.float32)
        data.init = GaussianCloud(c.means[idx] + jitter, c.f_dc[idx], c.f_rest[idx], c.opacity[idx],
                                  c.log_scales[idx], c.quats[idx])  # fmt: skip
    field = is_field_method(spec["method"])
    opts = spec.get("options", {})
    if field:  # the voxel-grid field's trainer, with the run's options (its grid schedule)
        try:
            from eigs.train.field.trainer import FieldTrainer
        except ImportError:  # before the train package's split (issue 47)
            from eigs.train.field_loop import FieldTrainer  # type: ignore[no-redef]
        tr = FieldTrainer(data, TrainConfig.from_dict({"method": spec["method"], **opts}), torch.device("cpu"))
    else:
        cfg = TrainConfig.from_dict({"method": spec["method"], "densify": False,
                                     "method_options": opts.get("method_options", {})})  # fmt: skip
        tr = Trainer(data, cfg, torch.device("cpu"))
    if hasattr(tr, "warm_up"):  # the Gaussian trainer builds its kernels first
        tr.warm_up()
    for _ in range(args.warm):
        tr.train_step()
    times = []
    if args.lockstep:  # one step per "step" line on stdin, its ms on stdout, until "stop"
        print("ready", flush=True)
        for line in sys.stdin:
            if line.strip() != "step":
                break
            t = time.perf_counter()
            tr.train_step()
            times.append((time.perf_counter() - t) * 1e3)
            print(f"{times[-1]:.6f}", flush=True)
    else:
        for _ in range(args.steps):
            t = time.perf_counter()
            tr.train_step()
            times.append((time.perf_counter() - t) * 1e3)
    size = n if field else len(tr.model)
    print(json.dumps({"ms": statistics.median(times), "gaussians": size, "width": data.width,
                      "height": data.height}))  # fmt: skip


def checkout(rev: str, work: Path) -> Path:
    """A worktree of ``rev`` under ``work`` (made once), its extension built."""
    path = work / f"rev-{rev}"
    if not path.is_dir():
        subprocess.run(["git", "worktree", "add", "--detach", "-f", str(path), rev], cwd=REPO, check=True,
                       capture_output=True)  # fmt: skip
    return path


def child_command(src: Path, case: str, args: argparse.Namespace) -> tuple[list[str], dict[str, str]]:
    """The command line and environment of one child: ``case`` timed with the package under ``src``."""
    if args.own_config:  # CONFIG of the checkout that ``src`` belongs to
        results, config, run, gaussians = case.split(":")
        case = ":".join([results, str(src.parent / config), run, gaussians])
    env = {**os.environ, "PYTHONPATH": str(src)}
    if args.omp_wait_policy != "inherit":
        env["OMP_WAIT_POLICY"] = args.omp_wait_policy.upper()
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", "--case", case, "--threads", str(args.threads),
           "--steps", str(args.steps), "--warm", str(args.warm)]  # fmt: skip
    if args.lockstep:
        cmd.append("--lockstep")
    return cmd, env


def run_child(src: Path, case: str, args: argparse.Namespace) -> dict:
    cmd, env = child_command(src, case, args)
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False, cwd=REPO)
    if proc.returncode != 0:
        raise SystemExit(f"{src}: {case} failed:\n{proc.stderr[-2000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def run_lockstep(trees: list[tuple[str, Path]], case: str, args: argparse.Namespace) -> dict[str, dict]:
    """Every tree's child started at once and stepped in turn, one step each, the first alternating, so that the
    builds' steps are compared within ~a step of each other (the host's speed drifts over seconds; docs/rasterizer.md).
    A child waits on its pipe between its steps, its threads idle: ``args.gap`` seconds pass before each step so that
    an idle team has gone to sleep and no spinning thread of one build runs under the other's step."""
    procs: dict[str, subprocess.Popen] = {}
    logs: dict[str, Any] = {}  # each child's stderr, in a file (a pipe left unread could fill and stall it)

    def failed(name: str) -> SystemExit:
        procs[name].kill()
        procs[name].wait()
        logs[name].seek(0)
        return SystemExit(f"{name}: {case} failed:\n{logs[name].read()[-2000:]}")

    try:
        for name, src in trees:
            cmd, env = child_command(src, case, args)
            logs[name] = tempfile.TemporaryFile("w+")
            procs[name] = subprocess.Popen(cmd, env=env, cwd=REPO, text=True, stdin=subprocess.PIPE,
                                           stdout=subprocess.PIPE, stderr=logs[name])  # fmt: skip
        for name, p in procs.items():
            if p.stdout.readline().strip() != "ready":
                raise failed(name)
        names = [name for name, _ in trees]
        for i in range(args.steps):
            for name in names if i % 2 == 0 else reversed(names):
                time.sleep(args.gap)
                procs[name].stdin.write("step\n")
                procs[name].stdin.flush()
                if not procs[name].stdout.readline().strip():
                    raise failed(name)
        out = {}
        for name, p in procs.items():
            stdout, _ = p.communicate("stop\n")
            if p.returncode != 0:
                raise failed(name)
            out[name] = json.loads(stdout.strip().splitlines()[-1])
        return out
    finally:
        for name, p in procs.items():
            if p.poll() is None:
                p.kill()
                p.wait()
            logs[name].close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--against", nargs="+", default=["357e960"], help="git revisions to time against")
    ap.add_argument("--case", action="append", help="RESULTS:CONFIG:RUN:GAUSSIANS (repeatable)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--steps", type=int, default=20, help="timed steps per child (the median is kept)")
    ap.add_argument("--warm", type=int, default=5, help="untimed steps first")
    ap.add_argument("--own-config", action="store_true", help="each revision's own CONFIG (default: this tree's)")
    ap.add_argument("--omp-wait-policy", choices=("inherit", "passive", "active"), default="inherit",
                    help="the children's OMP_WAIT_POLICY (inherit: this environment's, as `eigs train` runs; "
                    "passive: idle threads sleep at once, ~70 µs to wake a team on this VM)")  # fmt: skip
    ap.add_argument("--lockstep", action="store_true",
                    help="run the trees' children at once, stepping them in turn (one step each, alternating; "
                    "not with --omp-wait-policy active, whose idle threads spin without end)")  # fmt: skip
    ap.add_argument("--gap", type=float, default=0.05, help="with --lockstep: seconds idle before each step")
    ap.add_argument("--work", type=Path, default=Path("/tmp/eigs-step-ab"), help="where the worktrees go")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    from bench._report import add_out_argument, table, write_section

    add_out_argument(ap)
    args = ap.parse_args()
    if args.child:
        child(args)
        return
    cases = args.case or ["results/toy:config/toy.yaml:eigs+:0"]
    args.work.mkdir(parents=True, exist_ok=True)
    trees = {OURS: REPO / "src", **{rev: checkout(rev, args.work) / "src" for rev in args.against}}
    ms: dict[tuple[str, str], list[float]] = {}
    meta: dict[str, dict] = {}
    for rnd in range(args.rounds):
        order = list(trees.items()) if rnd % 2 == 0 else list(reversed(trees.items()))
        for case in cases:
            results = run_lockstep(order, case, args) if args.lockstep else None
            for name, src in order:
                res = results[name] if results else run_child(src, case, args)
                ms.setdefault((name, case), []).append(res["ms"])
                meta[case] = res
                print(f"round {rnd + 1} {case} {name}: {res['ms']:.1f} ms", flush=True)
    inherit = args.omp_wait_policy == "inherit"
    policy_name = (os.environ.get("OMP_WAIT_POLICY", "unset") if inherit else args.omp_wait_policy).lower()
    policy = f"`{policy_name}`" + (" (the environment's)" if inherit else "")
    rows = []
    for case in cases:
        _, config, run, _ = case.split(":")
        m = meta[case]
        ours = statistics.median(ms[(OURS, case)])
        for rev in args.against:
            theirs = statistics.median(ms[(rev, case)])
            per_round = [a / b for a, b in zip(ms[(OURS, case)], ms[(rev, case)], strict=True)]
            rows.append([f"`{run}` ({Path(case.split(':')[0]).name})", f"{m['width']}×{m['height']}",
                         f"{m['gaussians']:,}", f"`{rev}`", f"{theirs:.1f}", f"{ours:.1f}", f"{ours / theirs:.2f}",
                         f"{min(per_round):.2f}–{max(per_round):.2f}"])  # fmt: skip
    cols = ["run", "image", "Gaussians", "against", "ms then", "ms now", "now / then", "per round"]
    body = (
        f"One training step (`Trainer.train_step`, no densification, {args.threads} threads), this tree against "
        f"older revisions built from their own sources, "
        + ("each with the run's options of its own config file" if args.own_config else
           "all with the run's options of this tree's config file")
        + f", OpenMP wait policy {policy}, interleaved: {args.rounds} rounds, each a fresh process per "
        f"(revision, case) timing the median of {args.steps} steps after {args.warm} untimed ones"
        + (f" (the revisions' processes run at once and take their steps in turn, one each, {args.gap:g} s apart)"
           if args.lockstep else "")
        + "; the table gives "
        "the median over the rounds and the range of the per-round ratios (`bench/step_ab.py`).\n\n"
        + table(cols, rows) + "\n"
    )  # fmt: skip
    name, title = (
        ("step-ab-configured", "Training step against older revisions, each as configured (issue 46)")
        if args.own_config
        else ("step-ab", "Training step against older revisions (issue 46)")
    )
    write_section(name, title, body,
                  data={"cases": cases, "omp_wait_policy": policy_name, "threads": args.threads,
                        "ms": {f"{k[0]}|{k[1]}": v for k, v in ms.items()}}, out=args.out)  # fmt: skip
    print(body)


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    main()
