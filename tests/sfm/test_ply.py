"""3DGS PLY layout, round trip and the initialization rules."""

from __future__ import annotations

import numpy as np
import pytest
from plyfile import PlyData

from eigs.artifacts.gaussians import SH_C0, read_gaussian_ply, write_gaussian_ply
from eigs.errors import EigsError
from eigs.init.initialize import gaussians_from_points, initialize


def test_ply_round_trip_and_layout(tmp_path):
    rng = np.random.default_rng(0)
    xyz = rng.normal(size=(100, 3))
    rgb = rng.uniform(size=(100, 3))
    cloud = gaussians_from_points(xyz, rgb)
    cloud.f_rest[:] = rng.normal(size=cloud.f_rest.shape)
    path = tmp_path / "init.ply"
    write_gaussian_ply(cloud, path)
    names = PlyData.read(str(path))["vertex"].data.dtype.names
    expect = (
        ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
        + [f"f_rest_{i}" for i in range(45)]
        + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    )
    assert list(names) == expect
    assert all(PlyData.read(str(path))["vertex"].data.dtype[n] == np.dtype("<f4") for n in names)
    back = read_gaussian_ply(path)
    for name in ("means", "f_dc", "f_rest", "opacity", "log_scales", "quats"):
        np.testing.assert_array_equal(getattr(back, name), getattr(cloud, name))
    assert back.sh_degree == 3


def test_init_values_follow_the_3dgs_rules():
    # four points on a unit square's corners + one far away: 3-NN mean distances are known in closed form
    xyz = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
    rgb = np.array([[1.0, 0.5, 0.0]] * 4)
    c = gaussians_from_points(xyz, rgb, sh_degree=0)
    np.testing.assert_allclose(c.f_dc[0], [(1 - 0.5) / 0.28209479, 0, -0.5 / 0.28209479], rtol=1e-6)
    assert SH_C0 == pytest.approx(0.28209479)
    np.testing.assert_allclose(np.exp(c.log_scales), (2 + np.sqrt(2)) / 3, rtol=1e-6)
    np.testing.assert_allclose(1 / (1 + np.exp(-c.opacity)), 0.1, rtol=1e-6)
    np.testing.assert_array_equal(c.quats, np.tile([1, 0, 0, 0], (4, 1)))
    assert c.f_rest.shape == (4, 3, 0)


def test_random_fallback_when_points_are_too_few():
    cams = np.array([[-2.0, 0, 0], [2, 0, 0], [0, 2, 0], [0, 0, 2]])
    res = initialize(np.zeros((3, 3)), np.full((3, 3), 0.5), cams, min_points=100, n_random=500)
    assert res.n_sfm == 3 and res.n_random == 500 and len(res.cloud) == 503
    lo, hi = np.array(res.bounds[0]), np.array(res.bounds[1])
    assert np.all(res.cloud.means[3:] >= lo - 1e-6) and np.all(res.cloud.means[3:] <= hi + 1e-6)
    assert np.all(np.isfinite(res.cloud.log_scales))
    # duplicates do not produce -inf scales
    dup = gaussians_from_points(np.zeros((5, 3)), np.zeros((5, 3)))
    assert np.all(np.isfinite(dup.log_scales))


def test_read_rejects_non_gaussian_ply(tmp_path):
    from plyfile import PlyElement

    arr = np.zeros(3, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4")])
    p = tmp_path / "points.ply"
    PlyData([PlyElement.describe(arr, "vertex")]).write(str(p))
    with pytest.raises(EigsError, match="not a 3DGS PLY"):
        read_gaussian_ply(p)
    with pytest.raises(EigsError, match="no such PLY"):
        read_gaussian_ply(tmp_path / "absent.ply")
