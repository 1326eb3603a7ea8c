"""The consistency study (config/consistency.yaml, config/ladder.yaml's eigs-literal-b) measures the runs of the
default suite: its pairs must train exactly as config/config.yaml's runs, differing only in the consistency loss,
and its scenes must be the suite's scenes with only the shake changed."""

from __future__ import annotations

from pathlib import Path

import yaml

from tests.tables.test_table2_rows import differing, resolved

REPO = Path(__file__).resolve().parents[2]


def load(name: str) -> dict:
    return yaml.safe_load((REPO / "config" / name).read_text())


def test_the_study_pairs_are_the_suite_runs_and_differ_only_in_the_consistency_loss():
    suite, study, ladder = load("config.yaml"), load("consistency.yaml"), load("ladder.yaml")
    for run in ("eigs", "eigs-b"):
        assert resolved(study["runs"][run]) == resolved(suite["runs"][run]), run
    assert differing(resolved(study["runs"]["eigs"]), resolved(study["runs"]["eigs-b"])) == {"consistency"}
    literal, literal_b = resolved(suite["runs"]["eigs-literal"]), resolved(ladder["runs"]["eigs-literal-b"])
    assert differing(literal, literal_b) == {"consistency"}
    assert literal["consistency"] and not literal_b["consistency"]


def test_the_study_scenes_are_the_suite_scenes_with_twice_the_shake():
    suite, study = load("config.yaml"), load("consistency.yaml")
    assert set(study["scenes"]) == {f"{s}-shake2" for s in suite["scenes"]}
    for name, spec in suite["scenes"].items():
        other = study["scenes"][f"{name}-shake2"]
        assert other["builtin"] == spec["builtin"]
        assert other["overrides"] == {**spec["overrides"], "shake": 2 * spec["overrides"]["shake"]}
    assert study["edi"]["bins"] == [4] and study["sfm"] == suite["sfm"] and study["threads"] == suite["threads"]
