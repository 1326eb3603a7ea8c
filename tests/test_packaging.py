"""Pins stay consistent between pyproject.toml (pip) and environment.yml (conda); every import is declared."""

from __future__ import annotations

import tomllib
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]


def test_environment_yml_has_the_same_pins_as_pyproject():
    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    extras = project["optional-dependencies"]
    pins = set(project["dependencies"]) | set(extras["dev"]) | set(extras["slurm"])
    env = yaml.safe_load((REPO / "environment.yml").read_text())
    pip = next(d["pip"] for d in env["dependencies"] if isinstance(d, dict) and "pip" in d)
    assert set(pip) - {"-e ."} == pins
    assert all("==" in p for p in pins | {p for extra in extras.values() for p in extra}), "every dependency is pinned"
    assert "torch==2.13.0" in pins


def _imported_top_modules(root: Path) -> dict[str, str]:
    """{top-level module: first file importing it} over every ``.py`` file below ``root`` (absolute imports)."""
    import ast

    found: dict[str, str] = {}
    for path in sorted(root.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            for n in names:
                found.setdefault(n.split(".")[0], str(path.relative_to(REPO)))
    return found


def test_every_third_party_import_is_a_declared_dependency():
    """A module imported by src/, tests/ or bench/ is the standard library, ours, or comes from a distribution
    pinned in pyproject.toml (so a fresh `make venv` can run everything)."""
    import re
    import sys
    from importlib.metadata import packages_distributions

    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    pins = [*project["dependencies"], *(p for extra in project["optional-dependencies"].values() for p in extra)]
    declared = {re.split(r"[=<>!~\[ ]", p, maxsplit=1)[0].lower().replace("_", "-") for p in pins}
    local = {p.stem for d in ("tests", "bench") for p in (REPO / d).rglob("*.py")}  # helpers imported by name
    ours = {"eigs", "tests", "bench", "conftest"} | local
    dists = packages_distributions()
    missing = {}
    for d in ("src", "tests", "bench"):
        for mod, where in _imported_top_modules(REPO / d).items():
            if mod in sys.stdlib_module_names or mod in ours or mod == "__future__":
                continue
            owners = {x.lower().replace("_", "-") for x in dists.get(mod, [mod])}
            if not owners & declared:
                missing[mod] = where
    assert not missing, f"imported but not a declared dependency: {missing}"


def test_ci_script_sets_ci_itself(tmp_path):
    """`.ci/run` exports CI=true before `make test` and `make test-cluster` whatever its caller's environment
    (a stand-in `make` on PATH records what it sees)."""
    import os
    import stat
    import subprocess

    seen = tmp_path / "seen"
    fake = tmp_path / "make"
    fake.write_text(f'#!/usr/bin/env bash\necho "CI=${{CI:-}} $*" >> {seen}\n')
    fake.chmod(fake.stat().st_mode | stat.S_IEXEC)
    env = {k: v for k, v in os.environ.items() if k != "CI"}
    env["PATH"] = f"{tmp_path}{os.pathsep}{env['PATH']}"
    subprocess.run(["bash", str(REPO / ".ci" / "run")], env=env, check=True, timeout=60)
    assert seen.read_text().splitlines() == ["CI=true test", "CI=true test-cluster"]
