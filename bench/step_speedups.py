"""Per-run step-time factors (now / then) for ``bench/schedule.py --speedups`` from ``bench/step_ab.py``'s records.

Each input is the JSON a ``bench/step_ab.py --out DIR`` run writes (``DIR/step-ab-configured.json`` or
``DIR/step-ab.json``). A case's run gets the factor median(this tree's steps) / median(the revision's steps), the
medians taken over the rounds (each round's value is itself a child's median step). A run measured in several
inputs against the same revision pools their rounds; against another revision it keeps the last one given, so each
run can be timed against the revision its ledger rows were trained at (its newest one: the smallest gain, an
estimate on the safe side). ``--as NEW=RUN`` gives NEW the factor of RUN (a run
whose scene data is not on the measuring machine, timed through a sibling that takes the same step).

Run: ``.venv/bin/python bench/step_speedups.py A/step-ab-configured.json B/step-ab-configured.json
--as eigs-b6=eigs+ --out docs/suite/step_speedups.json [--section]`` (``--section``: also the table of every run's
factor, section "step-ab-runs" of docs/benchmarks.md).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from bench._report import _atomic_write, table, write_section  # noqa: E402
from bench.step_ab import OURS  # noqa: E402


def run_rounds(record: dict) -> dict[str, dict[str, list[float]]]:
    """One step_ab record's step times: {run: {OURS or revision: [ms per round]}}."""
    data = record.get("data") or {}
    out: dict[str, dict[str, list[float]]] = {}
    for key, values in data.get("ms", {}).items():
        tree, _, case = key.partition("|")
        parts = case.split(":")
        if len(parts) != 4 or not values:
            raise ValueError(f"not a step_ab record: key {key!r}")
        out.setdefault(parts[2], {})[tree] = [float(v) for v in values]
    return out


def factor(rounds: dict[str, list[float]]) -> tuple[str, float]:
    """(revision, now / then) of one run's rounds: exactly one revision besides this tree, finite positive times."""
    revs = [t for t in rounds if t != OURS]
    if OURS not in rounds or len(revs) != 1:
        raise ValueError(f"a run needs this tree and one revision, got {sorted(rounds)}")
    now, then = statistics.median(rounds[OURS]), statistics.median(rounds[revs[0]])
    if not (math.isfinite(now) and math.isfinite(then) and now > 0 and then > 0):
        raise ValueError(f"step times must be finite and > 0, got {now} and {then}")
    return revs[0], now / then


def speedups(records: list[dict], aliases: dict[str, str]) -> dict:
    """The speed-up document: per run its revision, rounds and factor (later records win; then the aliases)."""
    rounds: dict[str, dict[str, list[float]]] = {}
    for rec in records:
        for run, r in run_rounds(rec).items():
            if set(rounds.get(run, {})) == set(r):  # the same revision again: its rounds pooled
                rounds[run] = {tree: rounds[run][tree] + r[tree] for tree in r}
            else:
                rounds[run] = r
    against, factors = {}, {}
    for run, r in sorted(rounds.items()):
        against[run], factors[run] = factor(r)
    for new, run in aliases.items():
        if run not in factors:
            raise ValueError(f"--as {new}={run}: {run} was not measured")
        against[new], factors[new] = against[run], factors[run]
    return {"against": against, "aliases": aliases, "rounds": rounds,
            "factors": {k: round(v, 3) for k, v in sorted(factors.items())}}  # fmt: skip


def section_rows(doc: dict) -> list[list[str]]:
    """One table row per measured run: run, revision, ms then, ms now, now / then, the per-round ratios' range."""
    rows = []
    for run, rounds in doc["rounds"].items():
        rev = doc["against"][run]
        ours, theirs = rounds[OURS], rounds[rev]
        per_round = [a / b for a, b in zip(ours, theirs, strict=False)]
        rows.append([f"`{run}`", f"`{rev}`", f"{statistics.median(theirs):.1f}", f"{statistics.median(ours):.1f}",
                     f"{doc['factors'][run]:.2f}", f"{min(per_round):.2f}–{max(per_round):.2f}"])  # fmt: skip
    for new, run in doc["aliases"].items():
        rows.append([f"`{new}`", f"`{doc['against'][new]}`", "–", "–", f"{doc['factors'][new]:.2f}", f"as `{run}`"])
    return rows


def parse_aliases(items: list[str]) -> dict[str, str]:
    out = {}
    for item in items:
        new, sep, run = item.partition("=")
        if not sep or not new or not run:
            raise SystemExit(f"--as wants NEW=RUN, got {item!r}")
        out[new] = run
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("records", nargs="+", type=Path, help="bench/step_ab.py --out JSON files (later ones win)")
    ap.add_argument("--as", dest="aliases", action="append", default=[], help="NEW=RUN: NEW takes RUN's factor")
    ap.add_argument("--about", default="", help="a sentence on what was measured and how")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--section", action="store_true", help="write the table to docs/benchmarks.md (step-ab-runs)")
    args = ap.parse_args()
    records = []
    for path in args.records:
        try:
            records.append(json.loads(path.read_text()))
        except (OSError, json.JSONDecodeError) as err:
            raise SystemExit(f"{path}: cannot read a step_ab record: {err}") from None
    try:
        doc = speedups(records, parse_aliases(args.aliases))
    except ValueError as err:
        raise SystemExit(f"bench/step_speedups.py: {err}") from None
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True)
    doc = {"about": args.about, "measured_at": head.stdout.strip(), "date": records[-1].get("date"),
           "machine": records[-1].get("machine"), **doc}  # fmt: skip
    _atomic_write(args.out, json.dumps(doc, indent=1) + "\n")
    print(", ".join(f"{r} {f:.2f} (vs {doc['against'][r]})" for r, f in doc["factors"].items()))
    if args.section:
        cols = ["run", "against", "ms then", "ms now", "now / then", "per round"]
        intro = (
            "Each run's training step (`Trainer.train_step`, `bench/step_ab.py`), this tree against the revision "
            "named, interleaved; `now / then` is the ratio of the medians over the rounds, and "
            f"`{args.out.name}` holds every round (`bench/step_speedups.py`)."
        )
        body = f"{args.about}\n\n{intro}\n\n" + table(cols, section_rows(doc))
        write_section("step-ab-runs", "Every run's training step against the code it was trained with (issue 46)", body)


if __name__ == "__main__":
    main()
