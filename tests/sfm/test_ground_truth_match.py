"""SfM accuracy against a dense ground-truth trajectory looked up at the latent times, and a scene whose ground
truth cannot be matched to any latent time: the stage finishes and its report says so."""

from __future__ import annotations

import json

import numpy as np

from eigs.scene import Trajectory, read_scene, write_scene
from eigs.sfm.run import SfmConfig, run_sfm

from .fixtures import make_scene


def _with_trajectory(d: dict, t_us: np.ndarray, c2w: np.ndarray) -> None:
    scene = read_scene(d["scene"])
    scene.trajectory = Trajectory(t_us, c2w)
    write_scene(scene, d["scene"])


def test_ground_truth_trajectory_matched_at_latent_times_or_reported_unmatched(tmp_path):
    # estimated scene poses are no ground truth: the accuracy can only come from the trajectory
    d = make_scene(tmp_path / "a", views=5, bins=2, novel=0, source="estimated")
    t = read_scene(d["scene"]).poses.latent_t_us
    # the trajectory: exactly the latent poses at exactly their times (strictly increasing across views)
    _with_trajectory(d, t.ravel(), d["latent"].reshape(-1, 4, 4))
    rep = run_sfm(d["scene"], d["edi"], tmp_path / "a" / "sfm", cfg=SfmConfig(mode="given"))
    acc = rep["accuracy"]
    assert acc["n"] == t.size and acc["ate_rmse"] < 1e-6  # given mode reproduces the poses: ATE 0
    assert "trajectory" in acc["ground_truth"]

    # a trajectory entirely after the recording: nothing can be matched, the stage still finishes
    d = make_scene(tmp_path / "b", views=5, bins=2, novel=0, source="estimated")
    late = 10_000_000 + np.arange(4, dtype=np.int64) * 1000
    _with_trajectory(d, late, np.tile(np.eye(4), (4, 1, 1)))
    out = tmp_path / "b" / "sfm"
    rep = run_sfm(d["scene"], d["edi"], out, cfg=SfmConfig(mode="given"))
    on_disk = json.loads((out / "report.json").read_text())
    for r in (rep, on_disk):
        acc = r["accuracy"]
        assert acc["n"] == 0 and acc["ate_rmse"] is None
        assert "no registered latent pose has ground truth at its time" in acc["note"]
