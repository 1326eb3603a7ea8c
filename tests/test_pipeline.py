"""End to end on the toy scene: `snakemake all_sfm` (synth → edi → sfm → init) in a scratch directory."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from eigs.artifacts.edi import read_edi
from eigs.scene import read_scene

REPO = Path(__file__).resolve().parents[1]


def test_toy_pipeline_through_init(tmp_path):
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "snakemake",
            "all_sfm",
            "--cores",
            "2",
            "-s",
            str(REPO / "workflow" / "Snakefile"),
            "--directory",
            str(tmp_path),
            f"--configfile={REPO / 'config' / 'toy.yaml'}",
        ],
        capture_output=True,
        text=True,
        check=False,
        timeout=900,
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    res = tmp_path / "results" / "toy"
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
        assert any((tmp_path / "logs" / stage).iterdir()), f"no log for {stage}"
        assert any((tmp_path / "benchmarks" / stage).iterdir()), f"no benchmark for {stage}"
