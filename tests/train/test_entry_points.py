"""A method from another installed package: a throwaway distribution, built and installed here (pip, no network:
``--no-deps --no-build-isolation``) into a temporary target with an entry point in the group ``eigs.methods``, is
found by every process without an edit in src/eigs: ``eigs train --list`` lists it, ``snakemake -n`` plans its
training with its options checked, and Table I has its row with its label."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
PACKAGE = {
    "pyproject.toml": """
        [build-system]
        requires = ["setuptools"]
        build-backend = "setuptools.build_meta"

        [project]
        name = "eigs-toy-method"
        version = "0.1"

        [project.entry-points."eigs.methods"]
        toy-ep = "eigs_toy_method:SPEC"

        [tool.setuptools]
        packages = ["eigs_toy_method"]
    """,
    # what the catalog imports (no torch): the options and the entry
    "eigs_toy_method/__init__.py": """
        from dataclasses import dataclass

        from eigs.train.catalog import GAUSSIAN, MethodSpec
        from eigs.util.options import Options


        @dataclass(frozen=True)
        class ToyOptions(Options):
            gain: float = 1.0

            def problems(self):
                return [] if self.gain > 0 else ["gain must be > 0"]


        SPEC = MethodSpec("toy-ep", GAUSSIAN, "eigs_toy_method.method:Toy", ToyOptions,
                          "a throwaway method from another package", steps=7, label="Toy (entry point)")
    """,
    # what a run imports (torch): the class
    "eigs_toy_method/method.py": """
        from eigs.train.gaussian.methods import Blurry3DGS


        class Toy(Blurry3DGS):
            pass
    """,
}
CONFIG = """
scenes:
  toy: {builtin: toy}
runs:
  toy-ep: {method: toy-ep, options: {steps: 5, method_options: {gain: %s}}}
"""


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The throwaway distribution installed into a fresh directory (to go on PYTHONPATH)."""
    root = tmp_path_factory.mktemp("entry_point")
    for rel, body in PACKAGE.items():
        (root / "src" / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / "src" / rel).write_text(textwrap.dedent(body).lstrip())
    proc = subprocess.run(
        [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation", "--no-index",
         "--target", str(root / "site"), str(root / "src")],
        capture_output=True, text=True, check=False, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert list((root / "site").glob("eigs_toy_method-0.1.dist-info/entry_points.txt"))
    return root / "site"


def _env(site: Path) -> dict[str, str]:
    path = [str(site), str(REPO / "src"), os.environ.get("PYTHONPATH", "")]
    return {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in path if p)}


def _run(site: Path, *args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, check=False, env=_env(site),
                          cwd=cwd, timeout=600)  # fmt: skip


def test_the_method_is_listed_and_gets_a_table1_row(site):
    proc = _run(site, "-m", "eigs", "train", "--list")
    assert proc.returncode == 0, proc.stderr
    assert "toy-ep           a throwaway method from another package" in proc.stdout
    code = textwrap.dedent("""
        import sys
        from eigs.tables.build import build_table
        from eigs.tables.rows import configured_rows
        from eigs.train.resolve import check_run
        cfg = check_run("toy-ep", {"method": "toy-ep", "options": {"method_options": {"gain": 2}}})
        assert cfg.steps == 7, cfg.steps
        rows = configured_rows(None, ["toy-ep"])["table1"]
        assert rows["toy-ep"] == "toy-ep", rows
        table = build_table("table1", rows, {})
        assert [r.label for r in table.rows if r.key == "toy-ep"] == ["Toy (entry point)"], table.rows
        assert "torch" not in sys.modules
    """)
    proc = _run(site, "-c", code)
    assert proc.returncode == 0, proc.stderr


def test_the_workflow_plans_it_with_its_options_checked(site, tmp_path):
    cfg = tmp_path / "config.yaml"
    snakemake = ["-m", "snakemake", "all", "-n", "-p", "--cores", "1", "-s", str(REPO / "workflow" / "Snakefile"),
                 "--directory", str(tmp_path / "work"), f"--configfile={cfg}"]  # fmt: skip
    cfg.write_text(CONFIG % 2)
    proc = _run(site, *snakemake)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "results/toy/b4/toy-ep/model.ply" in proc.stdout
    assert '"toy-ep":"toy-ep"' in proc.stdout  # its Table I row, in the tables job's --tables
    cfg.write_text(CONFIG % 0)
    proc = _run(site, *snakemake)
    assert proc.returncode != 0
    assert "config: run toy-ep" in proc.stdout + proc.stderr and "gain must be > 0" in proc.stdout + proc.stderr
