"""The workflow killed anywhere resumes to the same results (issue: faults survived end to end).

The kill config (tests/faults/kill.yaml) runs once uninterrupted; then a chain of starts, each killed with SIGKILL to
its whole process group at a seeded instant (a rule, and a delay into its first job drawn from that job's duration in
the uninterrupted run), each followed by the recovery README.md gives (``snakemake --unlock``, then the same command).
After every kill, every file under results/ is either marked incomplete by Snakemake or opens and reads whole with a
reader of its type (:func:`tests.faults.harness.check_results`); at the end no temporary is left and the tables and
evaluations equal the uninterrupted run's, all but the wall-time columns (those differ between two uninterrupted runs).

CI runs four instants (EDI, training, evaluation, tables) from the uninterrupted run's folder with its scene file made
newer (everything from EDI on reruns), that run itself starting from the shared toy fixture's upstream; the full
sweep, ``make kill-sweep`` (EIGS_KILL_INSTANTS=21), starts from an empty folder and hits every rule at least once.
"""

from __future__ import annotations

import os
import random
import shutil
from pathlib import Path

import pytest

from tests.faults.harness import Instant, check_results, final_figures, recover, run_workflow, stage_durations

CONFIG = Path(__file__).with_name("kill.yaml")
# (rule, its benchmark name, kills in the full sweep), in the order the DAG runs them
RULES = [
    ("synth", "synth", 2),
    ("edi", "edi", 2),
    ("sfm_given", "sfm", 2),
    ("init", "init", 1),
    ("train", "train", 6),
    ("evaluate", "evaluate", 3),
    ("video", "video", 2),
    ("figures", "figures", 1),
    ("tables", "tables", 2),
]
CI_RULES = {"edi": 1, "train": 1, "evaluate": 1, "tables": 1}


def plan_instants(durations: dict[str, float], full: bool, seed: int = 48) -> list[Instant]:
    """Seeded instants in DAG order: per kill of a rule, a delay uniform in [5 %, 90 %] of its job's duration."""
    rng = random.Random(seed)
    out = []
    for rule, stage, n_full in RULES:
        n = n_full if full else CI_RULES.get(rule, 0)
        for _ in range(n):
            out.append(Instant(rule, rng.uniform(0.05, 0.9) * durations[stage]))
    return out


@pytest.fixture(scope="module")
def reference(tmp_path_factory, toy):
    """The kill config run once without a fault: its figures and its stages' durations. In CI it starts from a copy
    of the shared toy fixture's folder (synth … init done, config/toy.yaml's sections are the kill config's); the
    sweep runs every stage."""
    work = tmp_path_factory.mktemp("kill_reference")
    if not int(os.environ.get("EIGS_KILL_INSTANTS", "0")):
        shutil.copytree(toy.root, work, dirs_exist_ok=True, ignore=shutil.ignore_patterns("locks", "DONE"))
    outcome = run_workflow(work, CONFIG)
    assert outcome.returncode == 0, outcome.output[-3000:]
    return final_figures(work), stage_durations(work), work


@pytest.mark.slow
def test_killed_anywhere_resumes_to_the_same_results(reference, tmp_path):
    figures, durations, ref_work = reference
    n_instants = int(os.environ.get("EIGS_KILL_INSTANTS", "0"))
    instants = plan_instants(durations, full=n_instants > 0)
    assert not n_instants or len(instants) >= n_instants
    work = tmp_path / "work"
    if n_instants:  # the sweep starts from nothing
        work.mkdir()
        shutil.copytree(ref_work / "resources", work / "resources")  # fetched model files: not a stage under test
    else:  # CI: the uninterrupted run's folder with its scene made newer, so everything from EDI on runs again
        shutil.copytree(ref_work, work, ignore=shutil.ignore_patterns("locks"))
        (work / "results" / "toy" / "scene.h5").touch()
    hit: list[str] = []
    log: list[str] = []
    for instant in instants:
        if (work / ".snakemake" / "locks").is_dir() and any((work / ".snakemake" / "locks").iterdir()):
            recover(work, CONFIG)
        outcome = run_workflow(work, CONFIG, instant)
        if not outcome.killed:  # the chain's remaining instants fell after the end
            assert outcome.returncode == 0, outcome.output[-3000:]
            log.append(f"{instant}: not reached, the workflow ended")
            break
        hit.extend(outcome.running)
        problems, temps = check_results(work)
        log.append(f"{instant}: killed while {', '.join(outcome.running) or 'no job'} ran; temporaries: {temps}")
        assert not problems, f"after the kill at {instant}:\n" + "\n".join(problems)
    print("\n".join(log))
    recover(work, CONFIG)
    outcome = run_workflow(work, CONFIG)
    assert outcome.returncode == 0, outcome.output[-3000:]
    problems, temps = check_results(work)
    assert not problems, "\n".join(problems)
    assert not temps, f"temporaries left behind: {temps}"
    assert sum("killed while" in line for line in log) >= min(len(instants), 4), log
    if n_instants:  # the full sweep: every rule was running at some kill
        assert {r for r, _, _ in RULES} <= set(hit), (sorted(set(hit)), log)
    after = final_figures(work)
    assert after.keys() == figures.keys()
    for key, value in figures.items():
        assert after[key] == value, key
