"""The train rule in the DAG: run targets from `runs:`, options passed as JSON, the GPU request capped by Snakemake."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def dry_run(*args: str) -> str:
    proc = subprocess.run(
        [sys.executable, "-m", "snakemake", "all", "-n", "--forceall", "--cores", "2", *args],
        cwd=REPO, capture_output=True, text=True, check=False, timeout=600,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout


def train_jobs(out: str) -> list[str]:
    return re.findall(r"rule train:\n(?:    .*\n)*?    output: (results/\S+)/model\.ply", out)


def test_default_suite_trains_each_run_on_each_scene_and_oracle_only_with_ground_truth(tmp_path):
    out = dry_run("--configfile=config/config.yaml")
    jobs = sorted(train_jobs(out))
    scenes = ["blocks", "chair", "dish", "drums", "spheres", "tree"]
    b4 = ("3dgs", "edi-3dgs", "oracle", "deblurring-gs", "deblurring-gs+", "e2gs", "bad-gaussians", "besplat",
          "evagaussians", "eigs", "eigs-literal", "eigs+", "eigs-a", "eigs-b", "eigs-minus", "eigs-w64", "eigs-w128",
          "eigs-w512", "eigs-d2", "eigs-d4")  # fmt: skip
    want = [f"results/{s}/b4/{r}" for s in scenes for r in b4]
    want += [f"results/{s}/b{b}/eigs-b{b}" for s in scenes for b in (6, 8)]
    assert jobs == sorted(want)
    cfg = tmp_path / "c.yaml"
    (tmp_path / "x.h5").write_bytes(b"")  # an ingested scene: no ground truth, so no oracle run
    cfg.write_text(
        f"scenes:\n  toy: {{builtin: toy}}\n  mine: {{source: {tmp_path / 'x.h5'}, format: h5}}\n"
        "edi: {bins: [4, 6]}\n"
        "runs:\n  o: {method: oracle}\n  e6: {method: eigs, bins: 6, options: {steps: 7}}\n"
    )
    out = dry_run(f"--configfile={cfg}")
    assert sorted(train_jobs(out)) == ["results/mine/b6/e6", "results/toy/b4/o", "results/toy/b6/e6"]
    assert """--config '{"method":"eigs","steps":7}'""" in out


def test_gpu_request_is_capped_by_what_the_run_provides():
    out = dry_run("--configfile=config/toy.yaml")
    blocks = out.split("rule train:")[1:]
    assert blocks and all("gpu=0" in b.split("Shell command")[0] for b in blocks)
    out = dry_run("--configfile=config/toy.yaml", "--resources", "gpu=1")
    blocks = out.split("rule train:")[1:]
    assert blocks and all("gpu=1" in b.split("Shell command")[0] for b in blocks)
