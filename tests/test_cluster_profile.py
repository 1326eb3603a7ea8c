"""The SLURM workflow profile (workflow/profiles/slurm, docs/cluster.md) without a cluster: what it shares with the
default profile, that it does not cap GPU requests, the per-rule requests a dry run plans, and which rules stay
local. The live run against a real scheduler is tests/cluster/test_slurm_live.py."""

from __future__ import annotations

import re
import subprocess
import sys
import textwrap
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
PROFILES = REPO / "workflow" / "profiles"


def load(name: str) -> dict:
    return yaml.safe_load((PROFILES / name / "profile.yaml").read_text())


def test_slurm_profile_keeps_the_default_profile_but_not_its_gpu_limit():
    """A workflow profile replaces the default one whole, so every default key except the `gpu: 0` limit is
    repeated with the same value; site settings (`default-resources`: account, partition) are left to the user's
    own --profile, which a workflow-profile key of the same name would replace."""
    default, slurm = load("default"), load("slurm")
    assert default["resources"] == {"gpu": 0}
    for key, value in default.items():
        if key != "resources":
            assert slurm.get(key) == value, key
    assert "resources" not in slurm and "default-resources" not in slurm
    assert slurm["executor"] == "slurm"
    assert {"jobs", "retries", "latency-wait"} <= set(slurm)


def dry_run(tmp_path: Path, *profile: str) -> dict[str, list[dict[str, str]]]:
    """{rule: [resources of each planned job]} from a dry run of the toy DAG (`all`) in a scratch directory."""
    proc = subprocess.run(
        [sys.executable, "-m", "snakemake", "all", "-n", "--forceall", "-s", str(REPO / "workflow" / "Snakefile")]
        + ["--directory", str(tmp_path), f"--configfile={REPO / 'config' / 'toy.yaml'}", *profile],
        capture_output=True,
        text=True,
        check=False,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    jobs: dict[str, list[dict[str, str]]] = {}
    for block in re.split(r"\n(?=rule \w+:)", proc.stdout):
        head = re.match(r"rule (\w+):", block)
        res = re.search(r"\n\s+resources: (.*)", block)
        if head and res:
            jobs.setdefault(head.group(1), []).append(dict(kv.split("=", 1) for kv in res.group(1).split(", ")))
    return jobs


def test_cluster_dry_run_asks_a_gpu_for_train_and_evaluate_only(tmp_path):
    """With the SLURM profile every train and evaluate job asks for one GPU (the plugin turns it into
    sbatch --gpus=1) and gets the profile's runtime and memory; CPU stages ask for none. The default profile on
    the same DAG plans gpu=0."""
    slurm = load("slurm")["set-resources"]
    jobs = dry_run(tmp_path / "slurm", "--workflow-profile", str(PROFILES / "slurm"))
    assert {"synth", "edi", "init", "train", "evaluate"} <= set(jobs)
    assert {"sfm", "sfm_given"} & set(jobs)  # the toy scene allows its ground-truth poses: sfm_given
    for rule, planned in jobs.items():
        for res in planned:
            assert res.get("gpu", "0") == ("1" if rule in ("train", "evaluate") else "0"), (rule, res)
            for key, value in slurm.get(rule, {}).items():
                assert res[key] == str(value), (rule, key, res)
            if rule != "resources" and not re.fullmatch(r"all(_\w+)?", rule):  # local and target-only rules
                assert "runtime" in res, f"{rule} has no runtime (sbatch --time)"
    local = dry_run(tmp_path / "local")
    assert {res["gpu"] for res in local["train"]} == {"0"}


def test_only_the_download_rule_is_local(tmp_path):
    """Rules that do work run as cluster jobs, except `resources` (package-registry downloads), which runs where
    Snakemake runs; target-only rules (`all*`) have no job to submit."""
    code = textwrap.dedent(
        f"""
        from pathlib import Path
        from snakemake.api import SnakemakeApi
        from snakemake.settings.types import ConfigSettings, OutputSettings, ResourceSettings, StorageSettings
        with SnakemakeApi(OutputSettings()) as api:
            wf = api.workflow(
                resource_settings=ResourceSettings(),
                config_settings=ConfigSettings(configfiles=[Path({str(REPO / "config" / "toy.yaml")!r})]),
                storage_settings=StorageSettings(),
                snakefile=Path({str(REPO / "workflow" / "Snakefile")!r}),
                workdir=Path({str(tmp_path)!r}),
            )
            wf.dag()
            w = wf._workflow
            # is_local() is True for every rule in a local run; the declared ones are the cluster's local rules.
            print("LOCAL", *sorted(r.name for r in w.rules if r.name in w._localrules and not r.norun))
        """
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    line = next(ln for ln in proc.stdout.splitlines() if ln.startswith("LOCAL"))
    assert line.split()[1:] == ["resources"]


def test_shell_commands_use_no_absolute_paths(tmp_path):
    """Jobs run anywhere: every planned shell command of the default config refers to files relative to the
    working directory (no path of this checkout or of the machine)."""
    proc = subprocess.run(
        [sys.executable, "-m", "snakemake", "all", "resources", "-n", "--forceall", "-p"]
        + ["-s", str(REPO / "workflow" / "Snakefile"), "--directory", str(tmp_path)]
        + [f"--configfile={REPO / 'config' / 'config.yaml'}"],
        capture_output=True,
        text=True,
        check=False,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    commands = [ln.split(":", 1)[1].strip() for ln in proc.stdout.splitlines() if ln.startswith("Shell command:")]
    commands = [c for c in commands if c != "None"]  # target-only rules (all, all_*)
    assert len(commands) > 100 and all(c.startswith("eigs ") for c in commands), commands[:3]
    absolute = [c for c in commands if re.search(r"(^|[\s='\"])/", c)]
    assert not absolute, absolute[:3]
