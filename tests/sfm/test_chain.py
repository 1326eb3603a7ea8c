"""The real chain on built-in scenes: synth → edi → sfm (→ init), through the CLI."""

from __future__ import annotations

import json

import numpy as np
import pycolmap
import pytest

from eigs.artifacts.gaussians import read_gaussian_ply
from eigs.artifacts.poses import METHOD_GIVEN, read_poses, read_test_cameras
from eigs.cli import main
from eigs.metrics.trajectory import Sim3, extent
from eigs.scene import read_scene


def canonical_of(poses) -> Sim3:
    m = poses.canonical
    s = float(np.cbrt(np.linalg.det(m[:3, :3])))
    return Sim3(s, m[:3, :3] / s, m[:3, 3])


def surface_distance(builtin: str, scene, x: np.ndarray, factor: int = 4) -> np.ndarray:
    """Distance (scene units) of points ``x`` (N, 3) to the true surface along the viewing rays of the scene's
    sharp cameras: |depth of the point − rendered depth| at its pixel, the smallest over the cameras that see it
    (depth maps rendered at ``factor``× resolution by the synth ray caster)."""
    from eigs.synth.raycast import RayCaster
    from eigs.synth.scenes import get_spec

    spec = get_spec(builtin)
    caster = RayCaster(spec.build(), background=spec.background, lighting=spec.lighting)
    cam = scene.camera
    K = cam.K.copy()
    K[:2] *= factor
    w, h = cam.width * factor, cam.height * factor
    depth = caster.render(scene.sharp.c2w, K, w, h, supersample=1, want_depth=True).depth
    best = np.full(len(x), np.inf)
    for c2w, d in zip(scene.sharp.c2w, depth, strict=True):
        w2c = np.linalg.inv(c2w)
        pc = x @ w2c[:3, :3].T + w2c[:3, 3]
        z = pc[:, 2]
        uv = pc @ K.T
        with np.errstate(divide="ignore", invalid="ignore"):
            u, v = uv[:, 0] / z, uv[:, 1] / z
        ok = (z > 0) & (u >= 0) & (v >= 0) & (u < w) & (v < h)
        j = np.clip(np.nan_to_num(u).astype(int), 0, w - 1)
        i = np.clip(np.nan_to_num(v).astype(int), 0, h - 1)
        best = np.where(ok, np.minimum(best, np.abs(d[i, j] - z)), best)
    return best


@pytest.mark.slow
def test_toy_given_mode_chain(tmp_path):
    scene_h5, b4 = tmp_path / "scene.h5", tmp_path / "b4"
    assert main(["synth", "--scene", "toy", "-o", str(scene_h5), "--threads", "2"]) == 0
    assert (
        main(["edi", str(scene_h5), "-o", str(b4 / "edi.h5"), "--latent-dir", str(b4 / "latent"), "--bins", "4"]) == 0
    )
    sfm = b4 / "sfm"
    assert main(["sfm", str(scene_h5), str(b4 / "edi.h5"), "-o", str(sfm), "--latent-dir", str(b4 / "latent")]) == 0
    report = json.loads((sfm / "report.json").read_text())
    assert report["mode"] == "given" and report["registration"]["fraction"] == 1.0
    scene = read_scene(scene_h5, events=False)
    poses = read_poses(sfm)
    canon = canonical_of(poses)
    # poses reproduced exactly (the EDI latent times are the scene's)
    np.testing.assert_array_equal(poses.timestamps_us, scene.poses.latent_t_us)
    np.testing.assert_allclose(poses.c2w, canon.apply_c2w(scene.poses.latent_c2w), atol=1e-12)
    # triangulated points lie on the true surfaces
    rec = pycolmap.Reconstruction(str(sfm))
    xyz = np.array([p.xyz for p in rec.points3D.values()])
    assert len(xyz) >= 50
    d = surface_distance("toy", scene, canon.inverse().apply(xyz))
    ext = extent(scene.poses.latent_c2w.reshape(-1, 4, 4)[:, :3, 3])
    assert np.median(d[np.isfinite(d)]) <= 0.005 * ext
    tc = read_test_cameras(sfm)
    assert len(tc) == len(scene.sharp.t_us) and np.all(tc.method == METHOD_GIVEN)
    # initial Gaussians: the toy has few points, so random ones are added
    ply = b4 / "init.ply"
    assert main(["init", str(sfm), "-o", str(ply)]) == 0
    cloud = read_gaussian_ply(ply)
    assert len(cloud) == len(xyz) + 10_000
    np.testing.assert_allclose(cloud.means[: len(xyz)], xyz, atol=1e-5)


@pytest.mark.slow
@pytest.mark.shared
def test_real_slider_frames_register(shared_real, tmp_path):
    """ECD slider_depth (real DAVIS frames, no events, ground-truth poses), every second of its 87 frames (44, half
    the COLMAP time; all 87 registered too, with the same assertions): ingest → EDI (pass-through) → SfM. Every
    frame registers; the ATE against the ground truth interpolated to the frame times is reported."""
    src = shared_real / "ecd_slider_depth"
    scene_h5, b4 = tmp_path / "scene.h5", tmp_path / "b4"
    ingest = ["ingest", "--format", "txt", str(src), "-o", str(scene_h5), "--exposure-us", "0,1000", "--views", "::2"]
    assert main(ingest) == 0
    assert main(["edi", str(scene_h5), "-o", str(b4 / "edi.h5"), "--latent-dir", str(b4 / "latent")]) == 0
    sfm = b4 / "sfm"
    args = ["sfm", str(scene_h5), str(b4 / "edi.h5"), "-o", str(sfm), "--mode", "colmap", "--matcher", "sequential"]
    assert main([*args, "--threads", "2"]) == 0
    report = json.loads((sfm / "report.json").read_text())
    assert report["registration"]["registered"] == report["registration"]["images"] == 44
    acc = report["accuracy"]
    assert acc["alignment"] == "line+orientation"  # a slider: collinear centres
    assert acc["n"] >= 40  # frames inside the ground-truth time range
    print(f"slider ATE {1000 * acc['ate_rmse']:.2f} mm ({acc['ate_percent_of_extent']:.3f} % of {acc['extent']:.3f} m)")
    assert acc["ate_percent_of_extent"] < 1.0
