# Shared helpers: config validation, scene lists, wildcard constraints, stage targets.
import json
import re
import shlex

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


# --- sfm / init (rules/sfm.smk) -------------------------------------------------------------------------------
ALL_SCENES = sorted(SCENES)


def sfm_options(wildcards):
    """`eigs sfm` flags from the `sfm:` config section."""
    s = config.get("sfm", {})
    opts = [
        f"--mode {s.get('mode', 'auto')}",
        f"--matcher {s.get('matcher', 'auto')}",
        f"--min-registered-fraction {float(s.get('min_registered_fraction', 0.5))}",
    ]
    if not s.get("allow_given", True):
        opts.append("--no-given")
    if not s.get("interpolate_unregistered", True):
        opts.append("--no-interpolate")
    if s.get("global_mapping", False):
        opts.append("--global-mapping")
    if s.get("refine_intrinsics", False):
        opts.append("--refine-intrinsics")
    if not s.get("register_test_cameras", True):
        opts.append("--no-register-test")
    return " ".join(opts)


def init_options(wildcards):
    s = config.get("init", {})
    return (
        f"--min-points {int(s.get('min_points', 1000))} --random {int(s.get('random', 10000))} "
        f"--sh-degree {int(s.get('sh_degree', 3))}"
    )


# --- edi (rules/edi.smk) --------------------------------------------------------------------------------------
def edi_bins():
    """The configured bin counts (config `edi: bins:`, default [4])."""
    return [int(b) for b in config.get("edi", {}).get("bins", [4])]


def edi_options(wildcards):
    """`eigs edi` flags from the `edi:` config section (the bins come from the {bins} wildcard)."""
    e = config.get("edi", {})
    opts = [
        f"--mode {e.get('mode', 'auto')}",
        f"--threshold-scope {e.get('threshold_scope', 'scene')}",
        f"--mask-top {float(e.get('mask_top', 0.01))}",
        f"--mask-factor {float(e.get('mask_factor', 8.0))}",
    ]
    if e.get("threshold") is not None:
        opts.append(f"--threshold {float(e['threshold'])}")
    return " ".join(opts)


# --- train (rules/train.smk) ----------------------------------------------------------------------------------
RUNS = config.get("runs", {})


def run_bins(run):
    """B of a run (its `bins:`, else the first configured EDI bins)."""
    return int(RUNS[run].get("bins", edi_bins()[0]))


def scene_has_ground_truth(scene):
    s = SCENES[scene]
    return "builtin" in s or s.get("format") == "e2nerf-synthetic"


def run_scenes(run):
    """Scenes a run is trained on: its `scenes:` list, else every scene (methods that train on ground truth,
    such as `oracle`, only on scenes that have it)."""
    spec = RUNS[run]
    if "scenes" in spec:
        return [s for s in spec["scenes"] if s in SCENES]
    if spec["method"] == "oracle":
        return [s for s in ALL_SCENES if scene_has_ground_truth(s)]
    return ALL_SCENES


def train_targets():
    return [
        f"results/{scene}/b{run_bins(run)}/{run}/model.ply" for run in sorted(RUNS) for scene in run_scenes(run)
    ]


def train_config_json(wildcards):
    """The run's method and options as one shell-quoted JSON object for `eigs train --config`."""
    spec = RUNS[wildcards.run]
    if int(wildcards.bins) != run_bins(wildcards.run):
        raise ValueError(f"run {wildcards.run} is configured for B = {run_bins(wildcards.run)}, not {wildcards.bins}")
    values = {"method": spec["method"], **spec.get("options", {})}
    return shlex.quote(json.dumps(values, sort_keys=True, separators=(",", ":")))
