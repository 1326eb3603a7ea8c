"""One source of defaults per stage: the options dataclass. The config schema only types and bounds the keys
(no defaults of its own), the CLI flags default to "not given", and a rule passes its config section unchanged as
one JSON object (``--config``)."""

from __future__ import annotations

import argparse
import dataclasses
import json
import shlex
import subprocess
import sys
from pathlib import Path

import jsonschema
import pytest
import yaml

from eigs.edi import cli as edi_cli
from eigs.edi.options import EdiOptions
from eigs.evaluate.options import EvaluateOptions
from eigs.init import cli as init_cli
from eigs.init.options import InitOptions
from eigs.sfm import cli as sfm_cli
from eigs.sfm.options import ColmapOptions, SfmConfig
from eigs.util.options import accepted, choices

REPO = Path(__file__).resolve().parents[1]
SCHEMA = yaml.safe_load((REPO / "workflow" / "schemas" / "config.schema.yaml").read_text())
# each config section and its options dataclass (the section's keys are its config keys: eigs.util.options.accepted)
STAGES = {"edi": EdiOptions, "sfm": SfmConfig, "init": InitOptions, "evaluate": EvaluateOptions}


def _defaults(section: str) -> dict:
    """The dataclass defaults of a section's keys, flattened like the config section."""
    d = dataclasses.asdict(STAGES[section]())
    d.update(d.pop("colmap", {}))
    return {k: d[k] for k in accepted(STAGES[section])}


@pytest.mark.parametrize("section", sorted(STAGES))
def test_schema_keys_are_the_options_and_carry_no_defaults(section):
    props = SCHEMA["properties"][section]["properties"]
    assert set(props) == set(accepted(STAGES[section]))
    assert {k: p["default"] for k, p in props.items() if "default" in p} == {}, "defaults live in the dataclass"


@pytest.mark.parametrize("section", sorted(STAGES))
def test_dataclass_defaults_satisfy_the_schema(section):
    values = {k: v for k, v in _defaults(section).items() if not (section == "edi" and k == "bins")}
    jsonschema.validate(values, SCHEMA["properties"][section])


def _parse(module, argv: list[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    module.add_arguments(p)
    p.add_argument("--threads", type=int, default=None)
    p.add_argument("-v", "--verbose", action="store_true")
    return p.parse_args(argv)


def test_cli_without_flags_gives_the_dataclass_defaults():
    assert edi_cli.options(_parse(edi_cli, ["s.h5", "-o", "e.h5"])) == EdiOptions()
    assert init_cli.options(_parse(init_cli, ["sfm", "-o", "i.ply"])) == InitOptions()
    cfg = sfm_cli.options(_parse(sfm_cli, ["s.h5", "e.h5", "-o", "out", "--threads", "3"]))
    assert cfg == SfmConfig(colmap=ColmapOptions(num_threads=3))


def test_config_json_sets_options_and_flags_win():
    a = _parse(edi_cli, ["s", "-o", "e", "--config", '{"mask_top": 0.02, "mode": "e2nerf"}', "--mode", "estimated"])
    assert edi_cli.options(a) == EdiOptions(mask_top=0.02, mode="estimated")
    a = _parse(edi_cli, ["s", "-o", "e", "--config", '{"per_pixel_threshold": false}', "--per-pixel-threshold"])
    assert edi_cli.options(a).per_pixel_threshold is True
    a = _parse(sfm_cli, ["s", "e", "-o", "o", "--config", '{"matcher": "sequential", "allow_given": false}',
                         "--no-register-test", "--threads", "1"])  # fmt: skip
    cfg = sfm_cli.options(a)
    assert (cfg.colmap.matcher, cfg.allow_given, cfg.register_test_cameras) == ("sequential", False, False)
    a = _parse(init_cli, ["d", "-o", "i", "--config", '{"random": 5, "sh_degree": 1}', "--sh-degree", "2"])
    assert init_cli.options(a) == InitOptions(random=5, sh_degree=2)


def test_unknown_or_malformed_config_is_a_clear_error():
    from eigs.errors import EigsError

    with pytest.raises(EigsError, match="unknown option.*mask_topp"):
        edi_cli.options(_parse(edi_cli, ["s", "-o", "e", "--config", '{"mask_topp": 0.1}']))
    with pytest.raises(EigsError, match="not valid JSON"):
        init_cli.options(_parse(init_cli, ["d", "-o", "i", "--config", "{random: 5}"]))
    with pytest.raises(EigsError, match="unknown option.*matchr"):
        SfmConfig.from_dict({"matchr": "auto"})
    with pytest.raises(EigsError, match="--config: matcher.*'vocab' is not one of auto, exhaustive, sequential"):
        sfm_cli.options(_parse(sfm_cli, ["s", "e", "-o", "o", "--config", '{"matcher": "vocab"}']))
    with pytest.raises(EigsError, match="option mask_top must be float"):
        edi_cli.options(_parse(edi_cli, ["s", "-o", "e", "--config", '{"mask_top": "lots"}']))


def test_rules_pass_the_config_section_unchanged(tmp_path):
    """A dry run prints each upstream command with `--config JSON`: exactly the section's keys (edi without its
    list of bins), which the CLI turns into the expected options."""
    sections = {
        "edi": {"bins": [3], "mask_top": 0.02, "per_pixel_threshold": False},
        "sfm": {"matcher": "sequential", "min_registered_fraction": 0.25},
        "init": {"random": 500},
    }
    cfg = tmp_path / "c.yaml"
    cfg.write_text(yaml.safe_dump({"scenes": {"toy": {"builtin": "toy", "overrides": {"seed": 3}}}, **sections}))
    proc = subprocess.run(
        [sys.executable, "-m", "snakemake", "all_sfm", "-n", "-p", "--forceall", "--cores", "1", f"--configfile={cfg}"],
        cwd=REPO, capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stdout + proc.stderr
    passed = {}
    for line in proc.stdout.splitlines():
        line = line.strip().removeprefix("Shell command:").strip()
        if line.startswith("eigs ") and "--config" in line:
            words = shlex.split(line.split(">")[0])
            passed[words[1]] = json.loads(words[words.index("--config") + 1])
    assert passed == {
        "synth": {"seed": 3},
        "edi": {"mask_top": 0.02, "per_pixel_threshold": False},
        "sfm": sections["sfm"],
        "init": sections["init"],
    }
    edi = edi_cli.options(_parse(edi_cli, ["s", "-o", "e", "--config", json.dumps(passed["edi"])]))
    assert edi == EdiOptions(mask_top=0.02, per_pixel_threshold=False)


def test_schema_enums_are_the_codes():
    """Every enum of a stage section in the schema is the tuple the code accepts (the ``choice`` fields of the options
    dataclass, what its validator checks for the CLI and eigs.plan.check_sections; the schema repeats it for
    `snakemake --lint` and editors, and this test fails when the two drift)."""
    code = {(section, k): tuple(v) for section, cls in STAGES.items() for k, v in choices(cls).items()}
    schema = {(section, key): tuple(spec["enum"]) for section in STAGES
              for key, spec in SCHEMA["properties"][section]["properties"].items() if "enum" in spec}  # fmt: skip
    assert schema == code
