"""The toy scene through Snakemake (as CI and a fresh clone run it), and the `eigs synth` command line."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from eigs.cli import main
from eigs.scene import read_scene

REPO = Path(__file__).resolve().parents[2]


def test_toy_scene_through_snakemake(tmp_path):
    """`snakemake results/toy/scene.h5 --cores 2 --configfile=config/toy.yaml`, in a scratch working directory
    so the repository's results/ stays clean."""
    proc = subprocess.run(
        [sys.executable, "-m", "snakemake", "results/toy/scene.h5", "--cores", "2",
         f"--configfile={REPO / 'config/toy.yaml'}", "--snakefile", str(REPO / "workflow/Snakefile"),
         "--directory", str(tmp_path)],
        cwd=REPO, capture_output=True, text=True, timeout=300, check=False,
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    scene = read_scene(tmp_path / "results/toy/scene.h5")
    assert scene.name == "toy" and scene.synthetic
    assert scene.frames.blurry.shape == (8, 48, 64, 3)
    assert int((scene.sharp.kind == 1).sum()) == 4
    assert len(scene.events) > 1000
    assert scene.poses.latent_c2w.shape == (8, 5, 4, 4)
    sheet = tmp_path / "results/toy/contact_sheet.png"
    assert sheet.stat().st_size > 1000
    assert (tmp_path / "logs/synth/toy.log").exists()
    assert not (REPO / "results/toy/scene.h5").exists() or (REPO / "results/toy/scene.h5").stat().st_mtime < (
        tmp_path / "results/toy/scene.h5"
    ).stat().st_mtime  # nothing written into the repository


def test_cli_list(capsys):
    assert main(["synth", "--list"]) == 0
    out = capsys.readouterr().out
    for name in ("toy", "blocks", "chair", "tree", "dish", "spheres", "drums", "shake_rot_deg", "seed"):
        assert name in out


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--scene", "lego", "-o", "x.h5"], "unknown built-in scene 'lego'"),
        (["--scene", "toy", "--overrides", "{bad", "-o", "x.h5"], "not valid JSON"),
        (["--scene", "toy", "--overrides", "[1]", "-o", "x.h5"], "JSON object"),
        (["--scene", "toy", "--overrides", '{"shake": "lots"}', "-o", "x.h5"], "shake must be a number"),
        (["--scene", "toy", "--config", "/nonexistent.yaml", "-o", "x.h5"], "no such config file"),
        (["--scene", "toy"], "nothing to write"),
        (["-o", "x.h5"], "give a built-in scene name"),
    ],
)
def test_cli_errors_are_one_line(argv, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["synth", *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and err.startswith("eigs synth: error:") and err.count("\n") == 1
    assert not (tmp_path / "x.h5").exists()


def test_cli_config_then_overrides(tmp_path):
    from tests.synth.test_generate import SMALL

    cfg = tmp_path / "p.yaml"
    cfg.write_text("".join(f"{k}: {v}\n" for k, v in {**SMALL, "seed": 1, "n_train": 2}.items()))
    out = tmp_path / "s.h5"
    assert main(["synth", "--scene", "toy", "--config", str(cfg), "--overrides", json.dumps({"n_train": 1}),
                 "-o", str(out), "--contact-sheet", str(tmp_path / "c.png")]) == 0
    s = read_scene(out)
    assert s.n_views == 1 and s.camera.width == SMALL["width"]
    assert (tmp_path / "c.png").exists()
    assert np.all(s.frames.exposure_us[:, 1] - s.frames.exposure_us[:, 0] == SMALL["exposure_us"])
