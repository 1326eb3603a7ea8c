"""config/size800.yaml (issue 46, part 4) measures the suite's own runs at the E²NeRF synthetic size: `edi-3dgs` and
`eigs+` train exactly as config/config.yaml defines them (only the held-out scoring interval differs), on one built-in
scene at 800×800 with 30 training views."""

from __future__ import annotations

from pathlib import Path

import yaml

from tests.tables.test_table2_rows import differing, resolved

REPO = Path(__file__).resolve().parents[2]


def test_the_runs_are_the_suites_at_800x800():
    suite = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    study = yaml.safe_load((REPO / "config" / "size800.yaml").read_text())
    assert set(study["runs"]) == {"edi-3dgs", "eigs+"}
    for run, spec in study["runs"].items():
        assert differing(resolved(spec), resolved(suite["runs"][run])) <= {"train.eval_every"}, run
    (scene,) = study["scenes"].values()
    overrides = scene["overrides"]
    assert (overrides["width"], overrides["height"], overrides["n_train"]) == (800, 800, 30)
    assert overrides["shake"] == suite["scenes"][scene["builtin"]]["overrides"]["shake"]
    assert study["sfm"] == suite["sfm"] and 4 in suite["edi"]["bins"] and study["edi"]["bins"] == [4]
