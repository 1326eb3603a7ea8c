"""docs/architecture.md is true to the tree: every module it names (a ``src/eigs/...`` path, an ``eigs.x.y``
dotted name, a file of the package tree), rule and config exists; it names every package, rule and config. The
other docs that describe the code (docs/development.md, config/README.md, README.md) name no missing module, and
config/README.md names every config."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SRC = REPO / "src" / "eigs"
DOC = (REPO / "docs" / "architecture.md").read_text()


def dotted_exists(name: str, src: Path = SRC) -> bool:
    """Whether ``eigs.a.b[.attr]`` is a module of ``src`` or a top-level name of one (ast; nothing imported)."""
    parts = name.split(".")[1:]
    for cut in range(len(parts), -1, -1):
        base = src.joinpath(*parts[:cut])
        module = base / "__init__.py" if base.is_dir() else base.with_suffix(".py")
        if module.is_file():
            rest = parts[cut:]
            return not rest or (len(rest) == 1 and rest[0] in top_level_names(module))
    return False


def top_level_names(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names |= {t.id for t in targets if isinstance(t, ast.Name)}
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names |= {(a.asname or a.name).split(".")[0] for a in node.names}
    return names


def tree_files(doc: str) -> list[tuple[str, str]]:
    """(package, file) for every ``x.py`` of the package tree block (the block that starts with ``src/eigs/``);
    package "" for the top-level modules."""
    block = doc.split("```\nsrc/eigs/\n", 1)[1].split("```", 1)[0]
    out, package = [], ""
    head = r"^(?:\s+layer \d+\s+|\s{11}(?=\S))"  # where a package or top-level module starts its entry
    for line in block.splitlines():
        m = re.match(head + r"(\w+)/\s", line)
        if m:
            package = m.group(1)
        elif re.match(head + r"\w+\.py\s", line):
            package = ""
        out += [(package, f) for f in re.findall(r"\b(\w+\.py)\b", line)]
    return out


def defined_rules() -> set[str]:
    proc = subprocess.run(
        [sys.executable, "-m", "snakemake", "--list-rules", "-s", str(REPO / "workflow" / "Snakefile"),
         f"--configfile={REPO / 'config' / 'toy.yaml'}"],
        capture_output=True, text=True, check=False, cwd=REPO, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    return {line.strip() for line in proc.stdout.splitlines() if re.fullmatch(r"\s*\w+\s*", line)}


def named_rules(doc: str) -> set[str]:
    """The rules the stage table's first column and the aggregate-rule sentence name (backticked)."""
    table = [line.split("|")[1] for line in doc.splitlines() if line.startswith("| ") and "---" not in line][1:]
    aggregate = doc.split("aggregate rule", 1)[1].split(")", 1)[0]
    return {w for cell in [*table, aggregate] for w in re.findall(r"`(\w+)`", cell)}


def test_named_paths_and_modules_exist():
    paths = set(re.findall(r"\bsrc/eigs/[\w/.]*\w", DOC))
    assert paths and [p for p in paths if not (REPO / p).exists()] == []
    dotted = set(re.findall(r"\beigs(?:\.\w+)+", DOC))
    assert dotted and sorted(n for n in dotted if not dotted_exists(n)) == []
    missing = [(pkg, f) for pkg, f in tree_files(DOC)
               if not (list((SRC / pkg).rglob(f)) if pkg else (SRC / f).is_file())]  # fmt: skip
    assert missing == []


def test_config_readme_names_every_config():
    text = (REPO / "config" / "README.md").read_text()
    assert {p.name for p in (REPO / "config").glob("*.yaml")} - set(re.findall(r"`(\w+\.yaml)`", text)) == set()


def test_every_package_and_config_is_named():
    packages = {p.name for p in SRC.iterdir() if p.is_dir() and (p / "__init__.py").is_file()}
    named = {pkg for pkg, _ in tree_files(DOC)}
    assert packages - named == set()
    configs = {f"config/{p.name}" for p in (REPO / "config").glob("*.yaml")}
    mentioned = set(re.findall(r"\bconfig/\w+\.yaml\b", DOC))
    assert configs - mentioned == set() and mentioned - configs == set()


def test_every_rule_is_named_and_every_named_rule_exists():
    rules = defined_rules()
    assert "all" in rules and "train_field" in rules
    assert named_rules(DOC) - rules == set()
    mentioned = set(re.findall(r"`(\w+)`", DOC))
    assert rules - {"all"} - mentioned == set()


def test_the_checks_catch_a_stale_name(tmp_path):
    assert dotted_exists("eigs.train.catalog.METHODS") and dotted_exists("eigs.train.gaussian.deblur")
    assert not dotted_exists("eigs.io.cli") and not dotted_exists("eigs.train.catalog.GROUND_TRUTH_METHODS")
    doc = ("```\nsrc/eigs/\n  layer 6  train/   loop.py, gaussian/ (nope.py)\n                   data.py\n"
           "  layer 9  plan.py  x\n```\n")
    assert tree_files(doc) == [("train", "loop.py"), ("train", "nope.py"), ("train", "data.py"), ("", "plan.py")]
    assert named_rules("| stage (rules) | x |\n|---|---|\n| a (`sfm`, `nope`) | y |\naggregate rule (`all_x`)") == {
        "sfm", "nope", "all_x"}


@pytest.mark.parametrize("doc", ["docs/development.md", "config/README.md", "README.md"])
def test_other_docs_name_no_missing_module(doc):
    text = (REPO / doc).read_text()
    dotted = set(re.findall(r"\beigs(?:\.\w+)+", text)) - {"eigs.methods"}  # the entry-point group's name
    assert sorted(n for n in dotted if not dotted_exists(n)) == []
    assert [p for p in set(re.findall(r"\bsrc/eigs/[\w/.]*\w", text)) if not (REPO / p).exists()] == []
