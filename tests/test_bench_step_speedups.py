"""bench/step_speedups.py: step_ab records turned into the per-run factors bench/schedule.py reads."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from bench import schedule
from bench.step_speedups import factor, run_rounds, section_rows, speedups

REPO = Path(__file__).resolve().parents[1]


def record(rev: str, runs: dict[str, tuple[list[float], list[float]]]) -> dict:
    """A step_ab --out record: per run (this tree's ms per round, the revision's)."""
    ms = {}
    for run, (ours, theirs) in runs.items():
        case = f"results/chair:config/config.yaml:{run}:10000"
        ms[f"this tree|{case}"], ms[f"{rev}|{case}"] = ours, theirs
    return {"section": "step-ab-configured", "date": "2026-11-30", "machine": "test", "data": {"ms": ms}}


def test_factor_is_the_ratio_of_the_medians_over_the_rounds():
    # medians 60 (of 50, 60, 90) and 100 (of 100, 80, 120): 0.6, not the median of the per-round ratios (0.75)
    assert factor({"this tree": [50.0, 60.0, 90.0], "abc": [100.0, 80.0, 120.0]}) == ("abc", pytest.approx(0.6))
    with pytest.raises(ValueError, match="one revision"):
        factor({"this tree": [1.0], "a": [1.0], "b": [1.0]})
    with pytest.raises(ValueError, match="finite"):
        factor({"this tree": [float("nan")], "a": [1.0]})


def test_later_records_win_and_aliases_copy_a_measured_run():
    old = record("357e960", {"eigs+": ([70.0], [100.0]), "3dgs": ([60.0], [100.0])})
    new = record("869d8a6", {"eigs+": ([90.0], [100.0])})
    doc = speedups([old, new], {"eigs-b6": "eigs+"})
    assert doc["factors"] == {"3dgs": 0.6, "eigs+": 0.9, "eigs-b6": 0.9}
    assert doc["against"] == {"3dgs": "357e960", "eigs+": "869d8a6", "eigs-b6": "869d8a6"}
    with pytest.raises(ValueError, match="not measured"):
        speedups([old], {"eigs-b8": "eigs-b6"})
    assert run_rounds(new) == {"eigs+": {"this tree": [90.0], "869d8a6": [100.0]}}


def test_records_of_the_same_revision_pool_their_rounds():
    a = record("04f65a8", {"eigs-b6": ([110.0, 112.0], [100.0, 100.0])})
    b = record("04f65a8", {"eigs-b6": ([96.0, 95.0, 94.0], [100.0, 100.0, 100.0])})
    doc = speedups([a, b], {})
    assert doc["rounds"]["eigs-b6"]["this tree"] == [110.0, 112.0, 96.0, 95.0, 94.0]
    assert doc["factors"] == {"eigs-b6": 0.96}  # the median of the five rounds over the median of theirs


def test_the_written_file_is_what_schedule_reads(tmp_path):
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    a.write_text(json.dumps(record("357e960", {"nerf": ([72.0, 74.0], [100.0, 100.0])})))
    b.write_text(json.dumps(record("61f1220", {"edi-3dgs": ([45.0], [50.0])})))
    out = tmp_path / "speed.json"
    subprocess.run([sys.executable, str(REPO / "bench/step_speedups.py"), str(a), str(b), "--as", "oracle=edi-3dgs",
                    "--out", str(out)], check=True, capture_output=True, cwd=REPO)  # fmt: skip
    assert schedule.load_speedups(out) == {"edi-3dgs": 0.9, "nerf": 0.73, "oracle": 0.9}
    bad = subprocess.run([sys.executable, str(REPO / "bench/step_speedups.py"), str(a), "--as", "x", "--out",
                          str(out)], capture_output=True, text=True, cwd=REPO)  # fmt: skip
    assert bad.returncode != 0 and "NEW=RUN" in bad.stderr


def test_the_section_names_each_runs_revision_and_its_rounds():
    doc = speedups([record("61f1220", {"3dgs": ([30.0, 40.0], [50.0, 50.0])})], {"oracle": "3dgs"})
    assert section_rows(doc) == [
        ["`3dgs`", "`61f1220`", "50.0", "35.0", "0.70", "0.60–0.80"],
        ["`oracle`", "`61f1220`", "–", "–", "0.70", "as `3dgs`"],
    ]
