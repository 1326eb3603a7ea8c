"""The real-data route for simulated DAVIS346 recordings: config/davis346.yaml plans (dry run), and the command
line route synth → E²NeRF real layout → ingest (+ ground truth) → EDI runs at toy size."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from eigs.cli import main
from eigs.scene import read_scene

REPO = Path(__file__).resolve().parents[2]
TOY = {"width": 64, "height": 48, "n_train": 4, "n_novel": 2, "subframes": 8, "gap_subframes": 4,
       "lead_subframes": 1, "supersample": 1, "texture_size": 32}


def test_davis346_config_plans(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "snakemake", "-n", "-p", "all", "--cores", "2",
         f"--configfile={REPO / 'config/davis346.yaml'}", "--snakefile", str(REPO / "workflow/Snakefile"),
         "--directory", str(tmp_path)],
        cwd=REPO, capture_output=True, text=True, timeout=300, check=False,
    )
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-3000:]
    counts = dict(re.findall(r"^(\w[\w_]*)\s+(\d+)$", out, flags=re.M))
    cfg = yaml.safe_load((REPO / "config/davis346.yaml").read_text())
    n_scenes, n_runs = len(cfg["scenes"]), len(cfg["runs"])
    assert n_scenes == 5
    assert counts["synth_e2nerf_real"] == counts["ingest"] == counts["sfm"] == str(n_scenes)
    assert counts["train"] == str(n_scenes * n_runs)  # the oracle too: the merged ground truth has sharp images
    assert "sfm_given" not in counts
    for name, s in cfg["scenes"].items():
        assert s["source"] == f"results/{name}/e2nerf-real"
        gt = s["options"][s["options"].index("--groundtruth") + 1]
        assert gt == f"results/{name}/groundtruth.h5" and not gt.startswith(s["source"] + "/")
        assert f"--groundtruth {gt}" in out  # the ingest command merges it
    assert cfg["sfm"]["mode"] == "colmap" and cfg["sfm"]["allow_given"] is False
    # evaluation scores BRISQUE beside the hidden ground truth; the tables add the rank agreement
    evals = [line for line in out.splitlines() if line.startswith("Shell command: eigs evaluate")]
    assert len(evals) == n_scenes * n_runs and all("--hidden-ground-truth" in e for e in evals)
    assert "results/tables/brisque_rank.md" in out and "results/tables/brisque_rank.csv" in out


def test_command_line_route_toy(tmp_path):
    from eigs.artifacts.edi import read_edi
    from eigs.sfm.options import SfmConfig
    from eigs.sfm.run import resolve_mode

    layout, gt, scene, edi = (tmp_path / n for n in ("e2nerf-real", "groundtruth.h5", "scene.h5", "b4/edi.h5"))
    assert main(["synth", "--scene", "toy", "--preset", "davis346", "--overrides", json.dumps(TOY),
                 "--e2nerf-real-layout", str(layout), "--groundtruth-out", str(gt), "--image-format", "png"]) == 0
    assert not list(layout.rglob("*.h5"))
    assert main(["ingest", "--format", "e2nerf-real", str(layout), "--groundtruth", str(gt), "--camera-response",
                 "linear", "-o", str(scene)]) == 0
    s = read_scene(scene)
    assert s.frames.blurry.shape == (4, 48, 64, 3) and s.sharp is not None and s.poses.source == "ground-truth"
    assert main(["edi", str(scene), "-o", str(edi)]) == 0
    e = read_edi(edi)
    assert e.latent.shape == (4, 5, 48, 64, 3) and np.all(np.isfinite(e.latent))
    cfg = yaml.safe_load((REPO / "config/davis346.yaml").read_text())
    assert resolve_mode(SfmConfig.from_dict(cfg["sfm"]), s, str(scene))[0] == "colmap"


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--scene", "toy", "--preset", "davis999", "-o", "x.h5"], "preset must be null or one of"),
        (["--scene", "toy", "-o", "x.h5", "--groundtruth-out", "g.h5"], "only with --e2nerf-real-layout"),
    ],
)
def test_cli_errors(argv, message, capsys):
    assert main(["synth", *argv]) != 0
    assert message in capsys.readouterr().err
