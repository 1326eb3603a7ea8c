"""End to end on the toy scene: `snakemake all_sfm` (synth → edi → sfm → init) in a scratch directory (the shared
``toy`` fixture of tests/conftest.py, which the training tests read too)."""

from __future__ import annotations

import json

import numpy as np

from eigs.artifacts.edi import read_edi
from eigs.scene import read_scene


def test_toy_pipeline_through_init(toy):
    root = toy.root  # the workflow directory of the shared toy fixture (tests/conftest.py)
    res = root / "results" / "toy"
    scene = read_scene(res / "scene.h5")
    assert (scene.camera.width, scene.camera.height, scene.n_views) == (64, 48, 8)
    assert (res / "contact_sheet.png").stat().st_size > 0
    edi = read_edi(res / "b4" / "edi.h5")
    assert edi.latent.shape == (8, 5, 48, 64, 3)
    np.testing.assert_array_equal(edi.timestamps_us, scene.poses.latent_t_us)
    assert len(list((res / "b4" / "latent").glob("v*_k*.png"))) == 8 * 5
    report = json.loads((res / "b4" / "sfm" / "report.json").read_text())
    assert report["mode"] == "given"
    assert (res / "b4" / "init.ply").stat().st_size > 0
    for stage in ("synth", "edi", "sfm", "init"):
        assert any((root / "logs" / stage).iterdir()), f"no log for {stage}"
        assert any((root / "benchmarks" / stage).iterdir()), f"no benchmark for {stage}"
