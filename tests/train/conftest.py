"""Toy-scene artifacts (synth → edi → sfm → init through the workflow) shared by the training tests."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


@dataclass
class ToyArtifacts:
    root: Path

    @property
    def scene(self) -> Path:
        return self.root / "results" / "toy" / "scene.h5"

    @property
    def edi(self) -> Path:
        return self.root / "results" / "toy" / "b4" / "edi.h5"

    @property
    def sfm(self) -> Path:
        return self.root / "results" / "toy" / "b4" / "sfm"

    @property
    def init(self) -> Path:
        return self.root / "results" / "toy" / "b4" / "init.ply"

    def paths(self) -> tuple[Path, Path, Path, Path]:
        return self.scene, self.edi, self.sfm, self.init


@pytest.fixture(scope="session")
def toy(tmp_path_factory) -> ToyArtifacts:
    root = tmp_path_factory.mktemp("toy")
    proc = subprocess.run(
        [sys.executable, "-m", "snakemake", "all_sfm", "--cores", "2", "-s", str(REPO / "workflow" / "Snakefile"),
         "--directory", str(root), f"--configfile={REPO / 'config' / 'toy.yaml'}"],
        capture_output=True, text=True, check=False, timeout=900,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return ToyArtifacts(root)
