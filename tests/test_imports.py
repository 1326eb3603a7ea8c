"""The import rules of docs/architecture.md, enforced from the source (ast over src/eigs): the one-way rule between
stage packages, the layers (no arrow up), no import circle anywhere (imports inside functions and under
``TYPE_CHECKING`` count), and the torch-free modules (the catalog, every options module, the planner) checked in a
fresh interpreter."""

from __future__ import annotations

import ast
import subprocess
import sys
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
# modules any package may import: the method catalog imports no torch (test_torch_free_modules) and tables read
# Table I's default rows from it
SHARED = {"eigs.train.catalog"}
# The layers, bottom up: a package imports only packages of lower layers (``eigs`` is the package's __init__: its
# version). Within a layer, packages do not import each other (the stages: the one-way rule).
LAYERS = [
    {"eigs", "errors"},
    {"util"},
    {"scene", "artifacts"},
    {"render", "metrics"},
    {"losses"},
    {"ingest", "synth", "edi", "sfm", "init"},
    {"train"},
    {"evaluate"},
    {"tables", "view"},
    {"plan"},
    {"cli"},
    {"__main__"},
]
# Modules that import no torch, in a fresh interpreter: the method catalog, every options module, the run
# resolver, the planner (the workflow imports it while Snakemake plans) and the tables' rows.
TORCH_FREE = [
    "eigs.train.catalog", "eigs.train.resolve", "eigs.util.options", "eigs.train.config",
    "eigs.train.gaussian.options", "eigs.train.field.options", "eigs.ingest.options", "eigs.edi.options",
    "eigs.sfm.options", "eigs.init.options", "eigs.plan", "eigs.tables.rows",
]  # fmt: skip


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


def module_name(path: Path, src: Path) -> str:
    parts = path.relative_to(src.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def module_graph(src: Path) -> dict[str, set[str]]:
    """Module → the modules of ``src`` it imports: ``from p import x`` is module ``p.x`` when that is a module of
    ``src``, else ``p``."""
    paths = {module_name(p, src): p for p in sorted(src.rglob("*.py"))}
    graph: dict[str, set[str]] = {}
    for mod, path in paths.items():
        pkg = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
        edges = set()
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = pkg.split(".")
                    base = ".".join([*parts[: len(parts) - (node.level - 1)], *([base] if base else [])])
                names = [f"{base}.{a.name}" if f"{base}.{a.name}" in paths else base for a in node.names]
            else:
                continue
            edges |= {n for n in names if n in paths and n != mod}
        graph[mod] = edges
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Every import circle (a strongly connected component of more than one module), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out)


def layer_violations(graph: dict[str, set[str]]) -> list[str]:
    """Imports that point up the layers, or across packages of one layer (besides :data:`SHARED`)."""
    layer = {pkg: i for i, pkgs in enumerate(LAYERS) for pkg in pkgs}

    def package(mod: str) -> str:
        parts = mod.split(".")
        return parts[1] if len(parts) > 1 else parts[0]

    bad = []
    for mod, targets in sorted(graph.items()):
        a = package(mod)
        for t in sorted(targets):
            b = package(t)
            if a == b or t in SHARED:
                continue
            if a not in layer or b not in layer:
                bad.append(f"{mod} → {t}: package {a if a not in layer else b} is in no layer")
            elif layer[b] >= layer[a]:
                bad.append(f"{mod} → {t}: {a} (layer {layer[a]}) imports {b} (layer {layer[b]})")
    return bad


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


def test_no_import_circle_anywhere():
    assert circles(module_graph(SRC)) == []


def test_no_import_points_up_the_layers():
    graph = module_graph(SRC)
    assert {m.split(".")[1] for m in graph if "." in m} <= set().union(*LAYERS), "a package is in no layer"
    assert layer_violations(graph) == []


def test_torch_free_modules():
    code = f"import sys; import {', '.join(TORCH_FREE)}; assert 'torch' not in sys.modules, 'torch imported'"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr


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


def test_the_graph_catches_circles_and_upward_arrows(tmp_path):
    root = tmp_path / "eigs"
    files = {
        "__init__.py": "",
        "util/__init__.py": "",
        "util/a.py": "def f():\n    from eigs.util import b\n",  # hidden inside a function: still an edge
        "util/b.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .a import f\n",
        "scene/__init__.py": "",
        "scene/s.py": "from eigs.train.loop import fit\n",  # up the layers
        "train/__init__.py": "",
        "train/loop.py": "from eigs.scene import s\nfrom eigs.train.catalog import METHODS\n",
        "train/catalog.py": "",
        "tables/__init__.py": "",
        "tables/t.py": "from eigs.train.catalog import METHODS\n",  # shared: allowed
    }
    for rel, body in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(body)
    graph = module_graph(root)
    assert graph["eigs.train.loop"] == {"eigs.scene.s", "eigs.train.catalog"}
    assert circles(graph) == [["eigs.scene.s", "eigs.train.loop"], ["eigs.util.a", "eigs.util.b"]]
    assert layer_violations(graph) == ["eigs.scene.s → eigs.train.loop: scene (layer 2) imports train (layer 6)"]
