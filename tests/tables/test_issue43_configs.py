"""The issue-43 studies measure their source config's runs: config/latent_dssim.yaml and config/latent_dssim_d346.yaml
train `eigs+` exactly as config/config.yaml and config/davis346.yaml do, and `eigs+-ld` (weight 4 and D-SSIM) and
`eigs+-ds` (the D-SSIM alone) differing only in the sharp-frame term from the `eigs+` they were measured against
(before 2026-11-30: no latent D-SSIM, no `latent_weight_dark`); config/ceiling_d346.yaml's `oracle-ceiling` is
davis346's oracle trained on the 3DGS reference implementation's schedule; config/davis346_noise.yaml is davis346's
scenes with frame noise and its runs; config/seeds_d346.yaml two of davis346's runs with other seeds. All on the
source's scenes and upstream stages (results/<scene>/b4/ shared)."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from tests.tables.test_table2_rows import differing, resolved

REPO = Path(__file__).resolve().parents[2]


def load(name: str) -> dict:
    return yaml.safe_load((REPO / "config" / name).read_text())


# the candidates: their latent_weight and the options in which they differ from eigs+
CANDIDATES = {"eigs+-ld": (4.0, {"latent_weight", "latent_dssim"}), "eigs+-ds": (0.5, {"latent_dssim"}),
              "eigs+-l2d": (2.0, {"latent_weight", "latent_dssim"}),
              "eigs+-dsr": (0.5, {"latent_dssim", "train.ssim_range"})}


def same_upstream(base: dict, study: dict) -> None:
    assert all(study["scenes"][s] == base["scenes"][s] for s in study["scenes"])
    assert study["edi"]["bins"] == [4] and 4 in base["edi"]["bins"]
    for key in ("sfm", "threads", "init"):
        assert study.get(key) == base.get(key), key


@pytest.mark.parametrize(("base_name", "study_name"), [("config.yaml", "latent_dssim.yaml"),
                                                       ("davis346.yaml", "latent_dssim_d346.yaml")])
def test_the_candidate_differs_from_eigs_plus_only_in_the_sharp_frame_term(base_name, study_name):
    base, study = load(base_name), load(study_name)
    same_upstream(base, study)
    assert set(study["scenes"]) == set(base["scenes"])
    assert set(CANDIDATES) <= set(study["runs"])
    for run in set(study["runs"]) - set(CANDIDATES):
        assert resolved(study["runs"][run]) == resolved(base["runs"][run]), run
    plain = resolved(study["runs"]["eigs+"])
    assert (plain["latent_dssim"], plain["latent_weight_dark"]) == (True, 2.0)  # eigs+ since 2026-11-30
    plain = {**plain, "latent_dssim": False, "latent_weight_dark": 0.0}  # the eigs+ the candidates were measured on
    for run, (weight, changed) in CANDIDATES.items():
        candidate = resolved(study["runs"][run])
        assert differing(plain, candidate) == changed, run
        assert candidate["latent_weight"] == weight and candidate["latent_dssim"] is True, run


def test_the_ceiling_is_the_oracle_on_the_reference_schedule():
    base, study = load("davis346.yaml"), load("ceiling_d346.yaml")
    same_upstream(base, study)
    assert resolved(study["runs"]["oracle"]) == resolved(base["runs"]["oracle"])
    ceiling = resolved(study["runs"]["oracle-ceiling"])
    # Kerbl et al. 2023's released training arguments (iterations, position lr, SH degree, densification window,
    # interval and threshold, opacity reset interval); our threshold is in the same NDC units (docs/training.md)
    reference = {"train.steps": 30000, "train.lr_means": 1.6e-4, "train.lr_means_final": 1.6e-6, "train.sh_degree": 3,
                 "train.refine_start": 500, "train.refine_every": 100, "train.grow_grad2d": 2e-4,
                 "train.prune_opacity": 0.005, "train.reset_every": 3000}
    assert {k: ceiling[k] for k in reference} == reference
    assert ceiling["train.steps"] * ceiling["train.refine_stop_frac"] == 15000
    changed = differing(resolved(base["runs"]["oracle"]), ceiling)
    assert changed - {"train.eval_every", "train.checkpoint_every", "train.refine_stop_frac"} <= set(reference)


def test_the_noisy_scenes_are_davis346s_with_frame_noise_and_its_runs():
    base, study = load("davis346.yaml"), load("davis346_noise.yaml")
    assert {s.replace("d346n-", "d346-") for s in study["scenes"]} == set(base["scenes"])
    for name, scene in study["scenes"].items():
        clean = base["scenes"][name.replace("d346n-", "d346-")]
        sim = scene["simulate"]
        assert sim["overrides"].pop("frame_noise") == "davis346"
        assert sim == clean["simulate"], name
        assert scene["source"] == f"results/{name}/e2nerf-real" and scene["format"] == clean["format"]
        assert scene["options"] == [o.replace("d346-", "d346n-") for o in clean["options"]]
    for key in ("edi", "sfm", "threads", "init"):
        assert study.get(key) == base.get(key), key
    assert set(study["runs"]) == {"3dgs", "edi-3dgs", "eigs", "eigs+", "oracle"}
    for run, spec in study["runs"].items():
        assert resolved(spec) == resolved(base["runs"][run]), run


def test_the_seed_study_is_davis346s_runs_with_other_seeds():
    """config/seeds_d346.yaml shares results/d346-blocks with davis346.yaml: its seed-0 runs must be davis346's, and
    each seeded run must differ from its base in the seed alone (else its spread measures something else)."""
    base, study = load("davis346.yaml"), load("seeds_d346.yaml")
    same_upstream(base, study)
    assert set(study["scenes"]) == {"d346-blocks"}
    for run in ("edi-3dgs", "eigs+"):
        assert resolved(study["runs"][run]) == resolved(base["runs"][run]), run
        assert resolved(study["runs"][run])["train.seed"] == 0
        for seed in (1, 2):
            seeded = resolved(study["runs"][f"{run}-s{seed}"])
            assert differing(resolved(base["runs"][run]), seeded) == {"train.seed"} and seeded["train.seed"] == seed
    assert set(study["runs"]) == {"edi-3dgs", "eigs+", "edi-3dgs-s1", "edi-3dgs-s2", "eigs+-s1", "eigs+-s2"}
