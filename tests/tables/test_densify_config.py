"""The densification studies (config/densify.yaml at 346×260, config/densify_suite.yaml at 128×96; issue 43) measure
runs of config/davis346.yaml and config/config.yaml: each `-norms` run must train exactly as its base run but for the
densification statistic, the base runs and the scenes and upstream stages those of the source config (so
results/<scene>/ is shared). `eigs+-norms` was measured on the `eigs+` before 2026-11-30 (without the latent D-SSIM
and `latent_weight_dark`), which it stays."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from tests.tables.test_table2_rows import differing, resolved

REPO = Path(__file__).resolve().parents[2]
STUDIES = [("densify.yaml", "davis346.yaml"), ("densify_suite.yaml", "config.yaml")]


def load(name: str) -> dict:
    return yaml.safe_load((REPO / "config" / name).read_text())


@pytest.mark.parametrize(("study", "source"), STUDIES)
def test_each_norms_run_is_the_source_run_with_the_norm_sum_statistic(study, source):
    study_cfg, source_cfg = load(study), load(source)
    assert set(study_cfg["runs"]) == {"edi-3dgs", "eigs", "eigs-norms", "eigs+", "eigs+-norms"}
    for run in ("edi-3dgs", "eigs", "eigs+"):
        assert resolved(study_cfg["runs"][run]) == resolved(source_cfg["runs"][run]), run
    for run in ("eigs", "eigs+"):
        plain, norms = resolved(study_cfg["runs"][run]), resolved(study_cfg["runs"][f"{run}-norms"])
        if run == "eigs+":  # the eigs+ the study measured
            assert (plain["latent_dssim"], plain["latent_weight_dark"]) == (True, 2.0)
            plain = {**plain, "latent_dssim": False, "latent_weight_dark": 0.0}
        assert plain["train.grow_grad2d_renders"] == "vector_sum", run
        assert differing(plain, norms) == {"train.grow_grad2d_renders"}, run
        assert norms["train.grow_grad2d_renders"] == "norm_sum", run


@pytest.mark.parametrize(("study", "source"), STUDIES)
def test_the_scenes_and_upstream_stages_are_the_source_ones(study, source):
    study_cfg, source_cfg = load(study), load(source)
    assert study_cfg["scenes"] == source_cfg["scenes"]
    assert study_cfg["edi"]["bins"] == [4] and 4 in source_cfg["edi"]["bins"]
    for key in ("sfm", "threads", "init", "evaluate"):
        assert study_cfg.get(key) == source_cfg.get(key), key
