"""poses.h5 and test_cameras.h5 round trips and their error messages."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from eigs.artifacts.poses import (
    LatentPoses,
    TestCameras,
    read_poses,
    read_test_cameras,
    write_poses,
    write_test_cameras,
)
from eigs.errors import EigsError


def poses(v=3, l_=4) -> LatentPoses:
    c2w = np.tile(np.eye(4), (v, l_, 1, 1))
    c2w[1, 2] = np.nan
    reg = np.ones((v, l_), bool)
    reg[1, 2] = False
    return LatentPoses(
        c2w=c2w,
        timestamps_us=np.arange(v * l_, dtype=np.int64).reshape(v, l_),
        registered=reg,
        interpolated=np.zeros((v, l_), bool),
        sharp=np.zeros(v, bool),
        K=np.eye(3),
        width=64,
        height=48,
        mode="colmap",
    )


def test_poses_round_trip(tmp_path):
    p = poses()
    write_poses(p, tmp_path / "poses.h5")
    back = read_poses(tmp_path)  # the sfm/ directory works too
    for name in ("c2w", "timestamps_us", "registered", "interpolated", "sharp", "K", "canonical"):
        np.testing.assert_array_equal(getattr(back, name), getattr(p, name))
    assert back.mode == "colmap" and (back.width, back.height) == (64, 48)
    assert back.valid.sum() == 11 and not back.valid[1, 2]


def test_test_cameras_round_trip_and_errors(tmp_path):
    s = 2
    tc = TestCameras(
        c2w=np.tile(np.eye(4), (s, 1, 1)),
        K=np.tile(np.eye(3), (s, 1, 1)),
        width=8,
        height=6,
        index=np.arange(s),
        kind=np.array([0, 1], np.uint8),
        view=np.array([0, -1]),
        t_us=np.array([5, -1]),
        method=np.array([0, 1], np.uint8),
        reprojection_error_px=np.array([0.2, np.nan]),
        num_inliers=np.array([50, 0]),
    )
    write_test_cameras(tc, tmp_path / "test_cameras.h5")
    back = read_test_cameras(tmp_path / "test_cameras.h5")
    np.testing.assert_array_equal(back.reprojection_error_px, tc.reprojection_error_px)
    np.testing.assert_array_equal(back.view, tc.view)
    tc.c2w[0, 0, 0] = np.nan
    with pytest.raises(EigsError, match="NaN"):
        write_test_cameras(tc, tmp_path / "bad.h5")
    with pytest.raises(EigsError, match="no such test cameras file"):
        read_test_cameras(tmp_path / "absent.h5")
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f.attrs["format"] = "something"
    with pytest.raises(EigsError, match="not an eigs SfM poses file"):
        read_poses(tmp_path / "other.h5")
