# Shared helpers: config validation, scene lists, wildcard constraints, stage targets.
# Stage options: every default lives in the stage's options dataclass (eigs.events.options.EdiOptions,
# eigs.sfm.options.SfmConfig / InitOptions, eigs.synth.scenes.DEFAULTS, eigs.train.config.TrainConfig); the schema
# only types and bounds them, and a rule passes its config section unchanged as one JSON object (`--config`).
import json
import re
import shlex

from snakemake.utils import validate

from eigs.events.options import DEFAULT_BINS
from eigs.sfm.options import SfmConfig
from eigs.train.field_config import FIELD_METHODS
from eigs.train.method_inputs import EVENT_METHODS


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
    """Threads for a numeric rule (config `threads`; its default comes from the schema)."""
    return int(config["threads"])


def config_json(values):
    """One shell-quoted JSON object (sorted keys, so params compare equal between runs) for a stage's `--config`."""
    return shlex.quote(json.dumps(values, sort_keys=True, separators=(",", ":")))


def section_json(section, exclude=()):
    """The config section `section` (only the keys the config sets) as `config_json`."""
    return config_json({k: v for k, v in config.get(section, {}).items() if k not in exclude})


def synth_builtin(wildcards):
    return SCENES[wildcards.scene]["builtin"]


def synth_config(wildcards):
    """The scene's `overrides:` for `eigs synth --config` (defaults: eigs.synth.scenes)."""
    return config_json(SCENES[wildcards.scene].get("overrides", {}))


def ingest_source(wildcards):
    return SCENES[wildcards.scene]["source"]


def ingest_format(wildcards):
    return SCENES[wildcards.scene]["format"]


def ingest_options(wildcards):
    return " ".join(SCENES[wildcards.scene].get("options", []))


# --- sfm / init (rules/sfm.smk) -------------------------------------------------------------------------------
ALL_SCENES = sorted(SCENES)


def scene_sfm(scene):
    """The `sfm:` keys of a scene: the global section with the scene's own `sfm:` over it; `{scene}` in `path` is
    the scene name. Mode model without a path is a config error naming the scene."""
    values = {**config.get("sfm", {}), **SCENES[scene].get("sfm", {})}
    if "path" in values:
        values["path"] = values["path"].replace("{scene}", scene)
    if values.get("mode") == "model" and not values.get("path"):
        raise ValueError(f"config: scene {scene}: sfm mode model needs `path` (the COLMAP model directory)")
    return values


def sfm_given_scenes():
    """Built-in scenes whose SfM job uses their ground-truth poses instead of COLMAP (the sfm_given jobs); `sfm: mode:
    given`, or `auto` with `allow_given` (defaults: eigs.sfm.options.SfmConfig). A built-in scene stores
    ground-truth latent poses, so `eigs sfm` in auto mode would pick given poses anyway (eigs.sfm.run.resolve_mode);
    their own rule shows the skipped COLMAP mapping in a dry run. Ingested scenes keep the sfm jobs (auto
    mode decides from the file)."""
    default = SfmConfig()
    out = []
    for s in BUILTIN_SCENES:
        section = scene_sfm(s)
        mode = section.get("mode", default.mode)
        if mode == "given" or (mode == "auto" and section.get("allow_given", default.allow_given)):
            out.append(s)
    return out


SFM_MODEL_SCENES = [s for s in ALL_SCENES if scene_sfm(s).get("mode") == "model"]  # rule sfm_model
SFM_GIVEN_SCENES = sfm_given_scenes()
SFM_COLMAP_SCENES = [s for s in ALL_SCENES if s not in SFM_GIVEN_SCENES and s not in SFM_MODEL_SCENES]


def sfm_config(wildcards):
    """The scene's `sfm:` keys for `eigs sfm --config` (defaults: eigs.sfm.options.SfmConfig)."""
    return config_json(scene_sfm(wildcards.scene))


def sfm_model_path(wildcards):
    """Mode model: the scene's COLMAP model directory (an input, so a changed model reruns the job)."""
    return scene_sfm(wildcards.scene)["path"]


def init_config(wildcards):
    """The `init:` section for `eigs init --config` (defaults: eigs.sfm.options.InitOptions)."""
    return section_json("init")


# --- edi (rules/edi.smk) --------------------------------------------------------------------------------------
def scene_uses_events(scene):
    """False for a scene configured with `events: false` (a frames-only recording, or no events wanted): its
    edi_frames job passes the frames through (`eigs edi --no-events`) and no method that needs events trains on it."""
    return SCENES[scene].get("events", True) is not False


EVENT_SCENES = [s for s in ALL_SCENES if scene_uses_events(s)]  # rule edi
FRAMES_ONLY_SCENES = [s for s in ALL_SCENES if not scene_uses_events(s)]  # rule edi_frames


def edi_bins():
    """The configured bin counts (config `edi: bins:`, default [eigs.events.options.DEFAULT_BINS])."""
    return [int(b) for b in config.get("edi", {}).get("bins", [DEFAULT_BINS])]


def edi_config(wildcards):
    """The `edi:` section for `eigs edi --config`, without `bins` (those come from the {bins} wildcard;
    defaults: eigs.events.options.EdiOptions)."""
    return section_json("edi", exclude=("bins",))


# --- train (rules/train.smk) ----------------------------------------------------------------------------------
RUNS = config.get("runs", {})


def run_bins(run):
    """B of a run (its `bins:`, else the first configured EDI bins)."""
    return int(RUNS[run].get("bins", edi_bins()[0]))


def scene_has_ground_truth(scene):
    s = SCENES[scene]
    merged = "simulate" in s and "--groundtruth" in s.get("options", [])  # rules/synth.smk synth_e2nerf_real
    return "builtin" in s or s.get("format") == "e2nerf-synthetic" or merged


def run_scenes(run):
    """Scenes a run is trained on: its `scenes:` list, else every scene (methods that train on ground truth,
    such as `oracle`, only on scenes that have it; methods that need events, eigs.train.method_inputs.EVENT_METHODS,
    only on scenes that have them). A `scenes:` list naming an `events: false` scene for such a method is an error."""
    spec = RUNS[run]
    method = spec["method"]
    if "scenes" in spec:
        scenes = [s for s in spec["scenes"] if s in SCENES]
        frames_only = [s for s in scenes if not scene_uses_events(s)]
        if method in EVENT_METHODS and frames_only:
            raise ValueError(
                f"config: run {run} (method {method}, which needs events) lists scene(s) "
                f"{', '.join(frames_only)} configured with `events: false`; remove them from its `scenes:` or use a "
                "method that trains on the frames alone"
            )
        return scenes
    if method == "oracle":
        return [s for s in ALL_SCENES if scene_has_ground_truth(s)]
    if method in EVENT_METHODS:
        return EVENT_SCENES
    return ALL_SCENES


def run_model_file(run):
    """The model file of a run folder: model.npz for a radiance-field method (docs/training.md), else model.ply."""
    return "model.npz" if RUNS[run]["method"] in FIELD_METHODS else "model.ply"


for _run in RUNS:  # config errors of the runs' scene lists now, not when a rule first asks
    run_scenes(_run)
GAUSSIAN_RUNS = sorted(r for r in RUNS if run_model_file(r) == "model.ply")
FIELD_RUNS = sorted(r for r in RUNS if run_model_file(r) == "model.npz")


def run_model(wildcards):
    """Input function: the model file of the run folder of `wildcards` (scene, bins, run)."""
    return f"results/{wildcards.scene}/b{wildcards.bins}/{wildcards.run}/{run_model_file(wildcards.run)}"


def train_targets():
    return [
        f"results/{scene}/b{run_bins(run)}/{run}/{run_model_file(run)}"
        for run in sorted(RUNS)
        for scene in run_scenes(run)
    ]


def train_config_json(wildcards):
    """The run's method and options as one shell-quoted JSON object for `eigs train --config`."""
    spec = RUNS[wildcards.run]
    if int(wildcards.bins) != run_bins(wildcards.run):
        raise ValueError(f"run {wildcards.run} is configured for B = {run_bins(wildcards.run)}, not {wildcards.bins}")
    values = {"method": spec["method"], **spec.get("options", {})}
    return shlex.quote(json.dumps(values, sort_keys=True, separators=(",", ":")))
