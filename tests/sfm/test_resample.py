"""One SfM per scene: another B's latent poses read from the first B's SfM (`eigs sfm --mode resample`,
eigs.sfm.resample), against a camera path known in closed form, and the workflow's planning of it."""

from __future__ import annotations

import json

import numpy as np
from scipy.spatial.transform import Rotation

from eigs import plan
from eigs.artifacts.edi import EdiResult, write_edi
from eigs.artifacts.poses import read_poses
from eigs.cli import main
from eigs.sfm.resample import resample_latent_poses
from tests.sfm.test_model_mode import EXPOSURE, SHARP_VIEW, V, build_case

AXIS = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])


def path_c2w(t_us: np.ndarray, view: int) -> np.ndarray:
    """A path on which translation-linear, slerp interpolation is exact: the centre moves at constant velocity and
    the rotation turns at constant rate about a fixed axis ((…) times → (…, 4, 4))."""
    t = np.asarray(t_us, np.float64) * 1e-6
    out = np.tile(np.eye(4), t.shape + (1, 1))
    out[..., :3, :3] = (Rotation.from_rotvec([0.1 * view, 0.2, -0.1]) * Rotation.from_rotvec(
        np.multiply.outer(t, 3.0 * AXIS).reshape(-1, 3))).as_matrix().reshape(t.shape + (3, 3))  # fmt: skip
    out[..., :3, 3] = np.array([view, 0.0, 5.0]) + np.multiply.outer(t, [2.0, -1.0, 0.5])
    return out


def test_poses_at_the_new_times_follow_the_path():
    """B = 4 → B = 8 on a path linear in translation and of constant angular velocity: the shared times copy the
    base's poses bit for bit (registered as the base's were), the others match the path to float64 rounding."""
    starts = np.arange(3, dtype=np.int64) * 100_000
    t4 = starts[:, None] + np.arange(5) * 5_000
    t8 = starts[:, None] + np.arange(9) * 2_500
    base = np.stack([path_c2w(t4[v], v) for v in range(3)])
    reg = np.ones(t4.shape, bool)
    reg[1, 2] = False  # an interpolated base slot stays flagged interpolated where it is copied
    c2w, registered, interpolated = resample_latent_poses(base, t4, np.ones(t4.shape, bool), reg, t8,
                                                          np.zeros(3, bool))  # fmt: skip
    assert np.array_equal(c2w[:, ::2], base)
    assert np.array_equal(registered[:, ::2], reg) and not registered[:, 1::2].any()
    assert interpolated[:, 1::2].all() and np.array_equal(interpolated[:, ::2], ~reg)
    want = np.stack([path_c2w(t8[v], v) for v in range(3)])
    np.testing.assert_allclose(c2w, want, atol=1e-12, rtol=0)


def test_edges_sharp_views_missing_poses_and_times_outside():
    """A view without any valid base pose gets NaN; a sharp view copies its first slot everywhere (neither
    registered nor interpolated beyond it); times beyond the base's take its end pose."""
    t4 = np.array([[0, 10, 20], [0, 10, 20], [0, 10, 20]], np.int64)
    base = np.stack([path_c2w(t4[v], v) for v in range(3)])
    valid = np.ones(t4.shape, bool)
    valid[2] = False
    base[2] = np.nan
    query = np.array([[-5, 5, 25], [0, 5, 20], [0, 5, 20]], np.int64)
    c2w, reg, interp = resample_latent_poses(base, t4, valid, valid, query, np.array([False, True, False]))
    np.testing.assert_allclose(c2w[0, [0, 2]], base[0, [0, 2]], atol=1e-12, rtol=0)  # through slerp at the ends
    assert interp[0].all() and not reg[0].any()
    assert np.array_equal(c2w[1, 1], c2w[1, 0]) and np.array_equal(c2w[1, 2], base[1, 0])
    assert reg[1].tolist() == [True, False, False] and not interp[1].any()
    assert np.isnan(c2w[2]).all() and not (reg[2] | interp[2]).any()


def _edi_at(d, n_bins: int, ts: np.ndarray, sharp: np.ndarray, name: str) -> None:
    H, W = 24, 32
    write_edi(EdiResult(latent=np.zeros((V, n_bins + 1, H, W, 1), np.float32), timestamps_us=ts,
                        cum_counts=np.zeros((V, n_bins + 1, H, W), np.int32), threshold=np.full(V, 0.2), sharp=sharp,
                        event_count=np.zeros(V, np.int64), events_per_pixel=np.zeros(V), blur_extent_px=np.zeros(V),
                        mode="estimated", threshold_scope="scene", scene_name="named"),
              d / name)  # fmt: skip


def test_stage_resamples_a_finished_sfm(tmp_path, capsys):
    """`eigs sfm --mode resample --from b2/sfm` at B = 4: the shared latent times carry the base's poses exactly,
    the points and test cameras are the base's files, report.json says where they came from; a base of another
    base without its model is refused naming it."""
    case = build_case(tmp_path)
    d = case["dir"]
    base = d / "b2" / "sfm"
    assert main(["sfm", str(d / "scene.h5"), str(d / "edi.h5"), "-o", str(base), "--mode", "model", "--model",
                 str(d / "model"), "--no-plot"]) == 0  # fmt: skip
    sharp = np.zeros(V, bool)
    sharp[SHARP_VIEW] = True
    ts4 = case["starts"][:, None] + np.arange(5)[None, :] * (EXPOSURE // 4)
    _edi_at(d, 4, ts4, sharp, "edi4.h5")
    out = d / "b4" / "sfm"
    assert main(["sfm", str(d / "scene.h5"), str(d / "edi4.h5"), "-o", str(out), "--mode", "resample", "--from",
                 str(base), "--no-plot"]) == 0  # fmt: skip
    b2, b4 = read_poses(base), read_poses(out)
    assert np.array_equal(b4.c2w[:, ::2], b2.c2w) and np.array_equal(b4.canonical, b2.canonical)
    assert b4.mode == b2.mode and b4.c2w.shape == (V, 5, 4, 4) and np.isfinite(b4.c2w).all()
    moving = ~sharp
    assert b4.interpolated[moving][:, 1::2].all()
    for name in ("points3D.bin", "images.bin", "cameras.bin"):
        assert (out / name).read_bytes() == (base / name).read_bytes()
    rep = json.loads((out / "report.json").read_text())
    assert rep["mode"] == "resample" and rep["resample"]["base"] == str(base)
    assert rep["resample"]["interpolated"] == int(b4.interpolated.sum()) > 0
    import shutil

    broken = d / "broken"
    shutil.copytree(base, broken)
    (broken / "points3D.bin").unlink()  # an SfM output without its model
    code = main(["sfm", str(d / "scene.h5"), str(d / "edi4.h5"), "-o", str(d / "bad"), "--mode", "resample",
                 "--from", str(broken), "--no-plot"])  # fmt: skip
    assert code != 0 and not (d / "bad").exists()
    err = capsys.readouterr().err
    assert str(broken) in err and "points3D.bin" in err


def test_the_workflow_runs_colmap_once_per_scene():
    """COLMAP scenes at B = 6 and 8 read the B = 4 SfM (rule sfm_resample); given-pose scenes and scenes with
    share_across_bins false keep one SfM per B."""
    cfg = {
        "edi": {"bins": [4, 6, 8]},
        "scenes": {"a": {"builtin": "chair", "sfm": {"allow_given": False}}, "b": {"builtin": "toy"},
                   "c": {"builtin": "dish", "sfm": {"allow_given": False, "share_across_bins": False}}},
    }  # fmt: skip
    assert [plan.sfm_base_bins(cfg, "a", b) for b in (4, 6, 8)] == [None, 4, 4]
    assert [plan.sfm_base_bins(cfg, s, 8) for s in ("b", "c")] == [None, None]
    assert plan.sfm_shares_bins(cfg, "a") and not plan.sfm_shares_bins(cfg, "c")


def test_dry_run_schedules_colmap_once_per_scene(tmp_path):
    """`edi: bins: [4, 6]` on a COLMAP scene: one `sfm` job (B = 4) and one `sfm_resample` job (B = 6) that reads
    B = 4's sfm/; with share_across_bins false, two `sfm` jobs; a given-pose scene keeps `sfm_given` at every B."""
    from tests.test_workflow_skips import job_counts, snakemake

    cfg = {"scenes": {"a": {"builtin": "toy", "sfm": {"allow_given": False}}, "b": {"builtin": "toy"}},
           "edi": {"bins": [4, 6]}, "threads": 1}  # fmt: skip
    proc = snakemake(tmp_path, cfg, "all_sfm", "-n", "-p", "--forceall")
    counts = job_counts(proc.stdout)
    assert (counts.get("sfm"), counts.get("sfm_resample"), counts.get("sfm_given")) == (1, 1, 2), proc.stdout
    cmd = next(ln for ln in proc.stdout.splitlines() if "--mode resample" in ln)
    assert "results/a/b6/edi.h5" in cmd and "--from results/a/b4/sfm" in cmd
    cfg["scenes"]["a"]["sfm"]["share_across_bins"] = False
    proc = snakemake(tmp_path, cfg, "all_sfm", "-n", "-p", "--forceall")
    counts = job_counts(proc.stdout)
    assert (counts.get("sfm"), counts.get("sfm_resample")) == (2, None), proc.stdout
