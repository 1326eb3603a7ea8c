"""The synthetic generator's E²NeRF-layout export reads back to the same scene (issue 5 acceptance)."""

from __future__ import annotations

import numpy as np
import pytest

from eigs.scene import read_scene
from tests.ingest.conftest import run_ingest

SMALL = {"seed": 1, "n_train": 3, "n_novel": 2, "subframes": 16, "gap_subframes": 8, "width": 32, "height": 24}


@pytest.fixture(scope="module")
def generated():
    from eigs.synth.generate import generate

    return generate("toy", dict(SMALL))


@pytest.mark.parametrize("pre_latent", [True, False])
def test_export_reads_back(generated, tmp_path, pre_latent):
    from eigs.synth.export_e2nerf import write_e2nerf_synthetic

    g = generated.scene
    folder = tmp_path / "toy_e2nerf"
    write_e2nerf_synthetic(generated, folder, include_pre_latent=pre_latent)
    out = tmp_path / "scene.h5"
    assert run_ingest("e2nerf-synthetic", folder, out) == 0
    s = read_scene(out)

    np.testing.assert_array_equal(s.frames.blurry, g.frames.blurry)  # bit-exact
    assert np.abs(s.poses.latent_c2w - g.poses.latent_c2w).max() <= 1e-6  # after Blender → OpenCV
    np.testing.assert_allclose(s.camera.K, g.camera.K, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(s.poses.latent_t_us, g.poses.latent_t_us)
    np.testing.assert_array_equal(s.frames.exposure_us, g.frames.exposure_us)

    # events.pt = the generator's raw events binned with E²NeRF's edges: bins between latent poses, bin 0 starting
    # a quarter latent spacing before latent pose 0 (E²NeRF's 10 ms before pose 0) when pre_latent is set
    lat = g.poses.latent_t_us
    edges = lat.copy()
    if pre_latent:
        edges[:, 0] = lat[:, 0] - np.rint((lat[:, -1] - lat[:, 0]) / 16).astype(np.int64)
    np.testing.assert_array_equal(s.binned.bin_edges_us, edges)
    ev = g.events
    want = np.zeros((g.n_views, 4, g.camera.height, g.camera.width), np.int64)
    for v in range(g.n_views):
        b = np.searchsorted(edges[v], ev.t, side="right") - 1
        ok = (ev.t >= edges[v, 0]) & (ev.t < edges[v, -1])
        np.add.at(want[v], (b[ok], ev.y[ok].astype(int), ev.x[ok].astype(int)), ev.p[ok].astype(np.int64))
    assert np.abs(want).sum() > 0
    np.testing.assert_array_equal(s.binned.counts, want)

    # ground truth: blur views at the first latent pose, novel views
    gs = g.sharp
    n_pairs = min(g.n_views, int(np.count_nonzero(gs.kind == 1)))  # the layout pairs blur view k with novel view k
    for kind in (0, 1):
        got = s.sharp.kind == kind
        exp = (gs.kind == kind) & ((gs.view < n_pairs) if kind == 0 else True)
        np.testing.assert_array_equal(s.sharp.images[got], gs.images[exp])
        assert np.abs(s.sharp.c2w[got] - gs.c2w[exp]).max() <= 1e-6
        np.testing.assert_array_equal(s.sharp.view[got], gs.view[exp])
        np.testing.assert_array_equal(s.sharp.t_us[got], gs.t_us[exp])
    assert s.camera_response == g.camera_response and s.contrast_threshold == g.contrast_threshold
