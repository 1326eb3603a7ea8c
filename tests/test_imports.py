"""The one-way import rule of docs/architecture.md, enforced from the source (ast over src/eigs)."""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src" / "eigs"
STAGES = {"ingest", "edi", "sfm", "init", "synth"}
# packages a downstream package may import (besides itself)
ALLOWED = {
    "artifacts": {"errors", "util"},
    "losses": {"metrics", "errors", "util"},
    "train": {"artifacts", "render", "metrics", "scene", "util", "errors", "losses"},
    "evaluate": {"artifacts", "render", "metrics", "scene", "util", "errors", "losses"},
    "tables": {"artifacts", "render", "metrics", "scene", "util", "errors"},
}
NO_TORCH = {"tables", "artifacts"}
# modules any package may import: the method catalog imports no torch (tests/train/test_catalog.py) and tables read
# Table I's default rows from it
SHARED = {"eigs.train.catalog"}


def imports_of(path: Path, src: Path) -> list[tuple[str, int]]:
    """Absolute module names imported by a file under ``src`` (relative imports resolved against its package)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    pkg_parts = (src.name, *path.relative_to(src).parts[:-1])
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(a.name, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = ".".join(pkg_parts[: len(pkg_parts) - (node.level - 1)])
                out.append((f"{base}.{node.module}" if node.module else base, node.lineno))
            elif node.module:
                out.append((node.module, node.lineno))
    return out


def violations(src: Path) -> list[str]:
    bad = []
    for path in sorted(src.rglob("*.py")):
        rel = path.relative_to(src)
        if len(rel.parts) < 2:
            continue  # top-level modules (cli.py, errors.py) may import any stage
        owner = rel.parts[0]
        for name, line in imports_of(path, src):
            parts = name.split(".")
            if owner in NO_TORCH and parts[0] == "torch":
                bad.append(f"{rel}:{line} imports torch")
            if parts[0] != src.name or len(parts) < 2 or parts[1] == owner or name in SHARED:
                continue
            target = parts[1]
            if owner in STAGES and target in STAGES:
                bad.append(f"{rel}:{line} stage {owner} imports stage {target}")
            if owner in ALLOWED and target not in ALLOWED[owner]:
                bad.append(f"{rel}:{line} {owner} imports {target}")
            if owner in STAGES | {"render", "metrics", "scene", "util"} and target in {"train", "losses", "evaluate",
                                                                                          "tables"}:  # fmt: skip
                bad.append(f"{rel}:{line} {owner} reaches down to {target}")
    return bad


def test_the_package_keeps_the_import_rule():
    assert violations(SRC) == []


def test_the_checker_catches_a_broken_rule(tmp_path):
    root = tmp_path / "eigs"
    for pkg, body in {
        "sfm": "from eigs.edi.pipeline import x\n",  # a stage reaching into another stage
        "train": "from eigs.sfm import run\nimport eigs.artifacts.edi\n",
        "tables": "import torch\nfrom ..artifacts import poses\n",
        "render": "from eigs.train import loop\n",
    }.items():
        (root / pkg).mkdir(parents=True)
        (root / pkg / "__init__.py").write_text("")
        (root / pkg / "mod.py").write_text(body)
    got = violations(root)
    assert got == [
        "render/mod.py:1 render reaches down to train",
        "sfm/mod.py:1 stage sfm imports stage edi",
        "tables/mod.py:1 imports torch",
        "train/mod.py:1 train imports sfm",
    ], got
