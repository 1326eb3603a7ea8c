"""Round trip of the real-data route: ``eigs synth`` with the davis346 preset (toy-sized) → E²NeRF real layout
(no ground truth inside) → ``eigs ingest --format e2nerf-real`` (+ the ground-truth sidecar) → the scene equals
what the generator made, within the stated tolerances."""

from __future__ import annotations

import numpy as np
import pytest

from eigs.errors import EigsError
from eigs.ingest.e2nerf import REAL_EXPOSURE_US, ingest_e2nerf
from eigs.ingest.options import IngestOptions
from eigs.scene import read_scene
from eigs.synth.export_e2nerf_real import REAL_BIN_US, write_e2nerf_real
from eigs.synth.generate import generate

# the davis346 preset at a toy size: 4 views, 64×48, 8 sub-frame steps per 100 ms exposure, 1 s apart
TOY_D346 = {"preset": "davis346", "width": 64, "height": 48, "n_train": 4, "n_novel": 2, "subframes": 8,
            "gap_subframes": 4, "lead_subframes": 1, "supersample": 1, "texture_size": 32}
JPEG_MEAN_ABS_TOL = 2.0  # JPEG quality 95 on 8-bit frames: mean |Δ| per value (grey levels)
JPEG_PSNR_MIN = 35.0  # dB
EXPOSURE_TOL_US = 4  # E²NeRF's fixed [0, 100004] µs vs the generator's 100,000 µs exposure


@pytest.fixture(scope="module")
def gen():
    return generate("toy", TOY_D346, show_progress=False)


@pytest.fixture(scope="module")
def exported(gen, tmp_path_factory):
    root = tmp_path_factory.mktemp("real")
    out = {}
    for fmt in ("png", "jpg"):
        layout = root / fmt / "e2nerf-real"
        gt = root / fmt / "groundtruth.h5"
        write_e2nerf_real(gen, layout, groundtruth=gt, image_format=fmt)
        out[fmt] = (layout, gt)
    return out


def ingest(layout, gt, tmp_path, **kw):
    dst = tmp_path / "scene.h5"
    ingest_e2nerf("e2nerf-real", str(layout), dst, IngestOptions(groundtruth=None if gt is None else str(gt), **kw))
    return read_scene(dst)


def expected_bins(scene) -> np.ndarray:
    """Independent binning of the generator's raw events as E²NeRF's real preprocessing does it: per view, the
    exposure's events, bin int((t − start) / 25001), signed sum per pixel → (V, 4, H, W)."""
    ev, ex, cam = scene.events, scene.frames.exposure_us, scene.camera
    out = np.zeros((scene.n_views, 4, cam.height, cam.width), np.int64)
    for v in range(scene.n_views):
        sel = (ev.t >= ex[v, 0]) & (ev.t < ex[v, 1])
        for t, x, y, p in zip(ev.t[sel], ev.x[sel], ev.y[sel], ev.p[sel], strict=True):
            out[v, int((t - ex[v, 0]) / 25001), y, x] += p
    return out


def test_layout_holds_no_ground_truth(exported):
    layout, gt = exported["png"]
    names = sorted(p.relative_to(layout).as_posix() for p in layout.rglob("*") if p.is_file())
    assert names == ["events.pt", "images/000.png", "images/005.png", "images/010.png", "images/015.png",
                     "poses_bounds.npy"]
    assert gt.is_file() and layout not in gt.parents
    pb = np.load(layout / "poses_bounds.npy")
    assert pb.shape == (20, 17)
    assert np.unique(pb, axis=0).shape[0] == 1  # one placeholder row: no pose information


def test_round_trip_png_exact(gen, exported, tmp_path):
    s = ingest(*exported["png"], tmp_path)
    g = gen.scene
    np.testing.assert_array_equal(s.frames.blurry, g.frames.blurry)
    # intrinsics: the generator's K (hwf keeps fx; principal point W/2, H/2 as the generator places it)
    np.testing.assert_array_equal(s.camera.K, g.camera.K)
    assert (s.camera.width, s.camera.height) == (64, 48)
    # events: E²NeRF's real binning of the generator's raw events, exactly
    np.testing.assert_array_equal(s.binned.counts, expected_bins(g))
    # every exposure event is in some bin: the per-view signed totals agree with the raw stream
    for v in range(g.n_views):
        lo, hi = g.events.view_index[v]
        assert s.binned.counts[v].sum() == g.events.p[lo:hi].astype(np.int64).sum()
    # exposure windows: each view on its own clock, [0, 100004] vs the generator's [start, start + 100000)
    ex = g.frames.exposure_us
    assert np.all(s.frames.exposure_us == np.array(REAL_EXPOSURE_US))
    assert np.all(np.abs((ex[:, 1] - ex[:, 0]) - (s.frames.exposure_us[:, 1] - s.frames.exposure_us[:, 0]))
                  <= EXPOSURE_TOL_US)
    np.testing.assert_array_equal(s.binned.bin_edges_us, np.tile(REAL_BIN_US * np.arange(5), (4, 1)))


def test_round_trip_jpeg_within_tolerance(gen, exported, tmp_path):
    s = ingest(*exported["jpg"], tmp_path)
    a, b = s.frames.blurry.astype(np.float64), gen.scene.frames.blurry.astype(np.float64)
    assert np.abs(a - b).mean() < JPEG_MEAN_ABS_TOL
    assert 10 * np.log10(255.0**2 / np.mean((a - b) ** 2)) > JPEG_PSNR_MIN


def test_ground_truth_merged_for_scoring_only(gen, exported, tmp_path):
    from eigs.sfm.options import SfmConfig
    from eigs.sfm.run import resolve_mode

    layout, gt = exported["png"]
    bare = ingest(layout, None, tmp_path)
    assert bare.sharp is None and bare.poses.source == "estimated"  # the layout alone carries no truth
    s = ingest(layout, gt, tmp_path)
    g = gen.scene
    start = g.frames.exposure_us[:, 0]
    want = gen.path((start[:, None] + REAL_BIN_US * np.arange(5)[None]).ravel()).reshape(4, 5, 4, 4)
    np.testing.assert_allclose(s.poses.latent_c2w, want, atol=1e-12)
    assert s.poses.source == "ground-truth"
    np.testing.assert_array_equal(s.sharp.images, g.sharp.images)
    np.testing.assert_array_equal(s.sharp.kind, g.sharp.kind)
    np.testing.assert_array_equal(s.sharp.view, g.sharp.view)
    assert "e2nerf-real" in s.source  # EDI's auto mode still treats it as an E²NeRF layout
    # SfM with given poses not allowed (the davis346 config) runs COLMAP: the truth only scores it
    assert resolve_mode(SfmConfig(allow_given=False), s, "x")[0] == "colmap"
    assert resolve_mode(SfmConfig(mode="colmap"), s, "x")[0] == "colmap"


def test_ground_truth_mismatch_refused(exported, tmp_path):
    layout, gt = exported["png"]
    with pytest.raises(EigsError, match="ground-truth camera"):
        ingest(layout, gt, tmp_path, intrinsics="50,50,31.5,23.5")
    with pytest.raises(EigsError, match="no such ground-truth file"):
        ingest(layout, tmp_path / "missing.h5", tmp_path)
    with pytest.raises(EigsError, match="groundtruth"):
        ingest_e2nerf("e2nerf-synthetic", str(layout), tmp_path / "x.h5", IngestOptions(groundtruth=str(gt)))


def test_long_exposure_refused(tmp_path):
    g = generate("toy", {**TOY_D346, "exposure_us": 100_008, "subframes": 4, "n_train": 1, "n_novel": 0,
                         "period_us": 1_000_008, "gap_subframes": 1}, show_progress=False)
    with pytest.raises(EigsError, match="exposure longer"):
        write_e2nerf_real(g, tmp_path / "l", groundtruth=tmp_path / "gt.h5")
    assert not (tmp_path / "l").exists() and not (tmp_path / "gt.h5").exists()
