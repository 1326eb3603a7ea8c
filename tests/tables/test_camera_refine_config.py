"""The camera-refinement studies (issue 44) measure their source config's runs: config/camera_refine.yaml the default
suite's (config/config.yaml), config/camera_refine_d346.yaml config/davis346.yaml's. Each pair must train exactly as
the source run, the refined one differing only in camera_refine, on the source's scenes and upstream stages (so
results/<scene>/b4/ is shared), scored by both evaluation protocols."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from tests.tables.test_table2_rows import differing, resolved

REPO = Path(__file__).resolve().parents[2]


def load(name: str) -> dict:
    return yaml.safe_load((REPO / "config" / name).read_text())


@pytest.mark.parametrize(("base_name", "study_name"), [("config.yaml", "camera_refine.yaml"),
                                                       ("davis346.yaml", "camera_refine_d346.yaml")])
def test_each_pair_is_the_source_run_and_its_refined_twin(base_name, study_name):
    base, study = load(base_name), load(study_name)
    assert set(study["runs"]) == {f"{r}{s}" for r in ("edi-3dgs", "oracle", "eigs+") for s in ("", "-cam")}
    for run in ("edi-3dgs", "oracle", "eigs+"):
        plain, refined = resolved(study["runs"][run]), resolved(study["runs"][f"{run}-cam"])
        assert plain == resolved(base["runs"][run]), run
        assert differing(plain, refined) == {"train.camera_refine"} and refined["train.camera_refine"], run


def test_the_scenes_and_upstream_stages_are_the_suite_ones_and_both_protocols_are_scored():
    suite, study = load("config.yaml"), load("camera_refine.yaml")
    assert study["scenes"] == suite["scenes"]
    assert study["edi"]["bins"] == [4] and 4 in suite["edi"]["bins"]
    assert study["sfm"] == suite["sfm"] and study["threads"] == suite["threads"]
    assert study.get("init") == suite.get("init")
    assert study["evaluate"]["test_pose_iters"] > 0


def test_the_davis346_study_is_on_davis346_scenes_and_upstream():
    base, study = load("davis346.yaml"), load("camera_refine_d346.yaml")
    assert set(study["scenes"]) == {"d346-blocks", "d346-chair", "d346-drums"}
    assert all(study["scenes"][s] == base["scenes"][s] for s in study["scenes"])
    for key in ("edi", "sfm", "threads"):
        assert study[key] == base[key], key
    assert study.get("init") == base.get("init")
    assert study["evaluate"]["test_pose_iters"] > 0
