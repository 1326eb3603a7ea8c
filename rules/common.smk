# Shared helpers: config validation, scene lists, wildcard constraints, stage targets.
import json
import re

from snakemake.utils import validate


validate(config, schema="../workflow/schemas/config.schema.yaml")

SCENES = config["scenes"]
BUILTIN_SCENES = sorted(n for n, s in SCENES.items() if "builtin" in s)
INGESTED_SCENES = sorted(n for n, s in SCENES.items() if "source" in s)
# Targets each stage adds to `all` (rules/<stage>.smk extend this list).
STAGE_TARGETS = []


def names_regex(names):
    """A wildcard regex matching exactly these names (and nothing when the list is empty)."""
    return "|".join(re.escape(n) for n in names) if names else "(?!x)x"


def threads_for(stage):
    """Threads for a numeric rule (config `threads`)."""
    return int(config.get("threads", 2))


def synth_builtin(wildcards):
    return SCENES[wildcards.scene]["builtin"]


def synth_overrides(wildcards):
    """Deterministic JSON (sorted keys) so params compare equal between runs."""
    return json.dumps(SCENES[wildcards.scene].get("overrides", {}), sort_keys=True, separators=(",", ":"))


def ingest_source(wildcards):
    return SCENES[wildcards.scene]["source"]


def ingest_format(wildcards):
    return SCENES[wildcards.scene]["format"]


def ingest_options(wildcards):
    return " ".join(SCENES[wildcards.scene].get("options", []))
