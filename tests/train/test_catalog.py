"""The method catalog (eigs.train.catalog) and the one options validator (eigs.train.resolve) (no torch and no import
circle: tests/test_imports.py): a new method is one entry plus one class, and every config's runs resolve to the options
they had before the catalog (tests/train/data/resolved_runs.json, written by the code of 5f548ef; keys added since
enter it with their defaults: ``grow_grad2d_renders``, ``discrete_floor``, ``latent_dssim``, ``ssim_range``,
``latent_weight_dark``)."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import pytest
import yaml

from eigs.cli import main
from eigs.errors import EigsError
from eigs.tables.paper import TABLES
from eigs.tables.rows import table_rows
from eigs.train import catalog
from eigs.train.catalog import GAUSSIAN, METHODS, MethodSpec, method_class, register
from eigs.train.gaussian.methods import Method
from eigs.train.gaussian.options import MultiRenderOptions
from eigs.train.resolve import check_run, check_runs, method_options, train_config
from eigs.util.options import Options, options_json

REPO = Path(__file__).resolve().parents[2]
TRAIN = REPO / "src" / "eigs" / "train"


def test_every_entry_loads_its_class_and_its_recipe():
    for name, spec in METHODS.items():
        assert issubclass(method_class(name), Method) == (spec.family == GAUSSIAN), name
        assert isinstance(spec.defaults(), spec.options), name
    assert options_json(METHODS["eigs-b"].defaults()) == {**options_json(MultiRenderOptions()), "consistency": False}


def test_defaults_agree_with_the_losses():
    from eigs.losses.consistency import DEFAULT_DELTA, DEFAULT_REG

    o = MultiRenderOptions()
    assert (o.huber_delta, o.consis_reg) == (DEFAULT_DELTA, DEFAULT_REG)


def resolved_runs() -> list[tuple[str, str, dict]]:
    out = []
    for path in sorted((REPO / "config").glob("*.yaml")):
        runs = (yaml.safe_load(path.read_text()) or {}).get("runs") or {}
        out += [(path.name, run, spec) for run, spec in sorted(runs.items())]
    return out


def test_every_config_run_resolves_as_before():
    """TrainConfig, the method options with their defaults, and the JSON rule train passes (train_config_json)."""
    snapshot = json.loads((Path(__file__).parent / "data" / "resolved_runs.json").read_text())
    runs = resolved_runs()
    assert {(f, r) for f, r, _ in runs} == {(f, r) for f, runs in snapshot.items() for r in runs}
    for name, run, spec in runs:
        check_run(run, spec)
        text = json.dumps({"method": spec["method"], **spec.get("options", {})}, sort_keys=True, separators=(",", ":"))
        cfg = train_config(json.loads(text), "--config")
        got = {"config_json": text, "train": cfg.to_dict(), "method_options": options_json(method_options(cfg))}
        assert json.dumps(got, sort_keys=True) == json.dumps(snapshot[name][run], sort_keys=True), (name, run)


@pytest.mark.parametrize(
    ("spec", "words"),
    [
        ({"method": "eigs", "options": {"method_options": {"lamda_event": 1}}}, ["lamda_event", "accepted: ade,"]),
        ({"method": "eigs", "options": {"stepz": 5}}, ["stepz", "accepted: method, steps,"]),
        ({"method": "nerf", "options": {"method_options": {"kernel_points": 3}}}, ["kernel_points", "batch_rays"]),
        ({"method": "besplat", "options": {"method_options": {"mode": "spline"}}}, ["mode must be one of"]),
        ({"method": "eigs", "options": {"method_options": {"width": 2.5}}}, ["option width must be int"]),
        ({"method": "nope"}, ["unknown method 'nope'"]),
        ({"method": "eigs", "option": {}}, ["unknown key(s) option", "accepted: method, bins, options, scenes"]),
    ],
)
def test_a_bad_run_is_one_line_naming_the_run_and_the_key(spec, words):
    with pytest.raises(EigsError) as err:
        check_runs({"my-run": spec})
    msg = str(err.value)
    assert "\n" not in msg and "my-run" in msg and all(w in msg for w in words), msg


def test_table1_rows_follow_the_paper_then_the_catalog():
    """Table I's rows: the paper's in its order, then the catalog's other Table I methods in catalog order (a new
    method needs no edit here), each row's run of its own name."""
    rows = table_rows()["table1"]
    assert all(k == v for k, v in rows.items())
    paper = list(TABLES["table1"]["rows"])
    assert list(rows)[: len(paper)] == paper
    assert list(rows)[len(paper):] == [n for n, s in METHODS.items() if s.table1 and n not in paper]


def test_a_new_method_is_one_entry_and_one_class(tmp_path, monkeypatch, capsys):
    (tmp_path / "toy_method.py").write_text(
        textwrap.dedent("""
        from dataclasses import dataclass
        from eigs.train.gaussian.methods import Method
        from eigs.util.options import Options

        @dataclass(frozen=True)
        class ToyOptions(Options):
            gain: float = 1.0

            def problems(self):
                return [] if self.gain > 0 else ["gain must be > 0"]

        class Toy(Method):
            def n_samples(self):
                return 1

            def step(self, model, sample, step, sh_degree):
                raise NotImplementedError
    """)
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(catalog, "METHODS", dict(METHODS))
    import eigs.tables.rows as rows

    monkeypatch.setattr(rows, "METHODS", catalog.METHODS)
    toy_options = __import__("toy_method").ToyOptions
    register(MethodSpec("toy", GAUSSIAN, "toy_method:Toy", toy_options, "a throwaway method", steps=7))
    assert main(["train", "--list"]) == 0
    assert "toy              a throwaway method" in capsys.readouterr().out
    cfg = check_run("toy-run", {"method": "toy", "options": {"method_options": {"gain": 2}}})
    assert cfg.steps == 7 and method_options(cfg) == toy_options(gain=2.0)
    with pytest.raises(EigsError, match="toy-run.*unknown option.*gian; accepted: gain"):
        check_run("toy-run", {"method": "toy", "options": {"method_options": {"gian": 2}}})
    with pytest.raises(EigsError, match="gain must be > 0"):
        check_run("toy-run", {"method": "toy", "options": {"method_options": {"gain": 0}}})
    assert table_rows()["table1"]["toy"] == "toy"
    assert method_class("toy").__name__ == "Toy" and issubclass(method_class("toy"), Method)
    assert catalog.METHODS["toy"].model_file == "model.ply" and isinstance(toy_options(), Options)
    assert "toy" not in METHODS  # the real catalog is untouched
