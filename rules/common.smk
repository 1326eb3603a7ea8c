# Shared helpers: config validation, scene lists, wildcard constraints, stage targets. Run planning (which scenes, SfM
# rule, runs per scene, B, model file) is eigs.plan's, shared with bench/schedule.py; this file binds it to `config`.
# Stage options: every default lives in the stage's options dataclass (eigs.edi.options.EdiOptions,
# eigs.sfm.options.SfmConfig, eigs.init.options.InitOptions, eigs.synth.scenes.DEFAULTS, eigs.train.config.TrainConfig);
# the schema only types and bounds them, and a rule passes its config section unchanged as one JSON object (`--config`).
import json
import re
import shlex

from snakemake.utils import validate

from eigs import plan
from eigs.artifacts import run as run_folder
from eigs.train.resolve import check_runs


# the stage sections in Python first (one line naming the key and the accepted keys or values), then the schema
plan.check_sections(config)
validate(config, schema="../workflow/schemas/config.schema.yaml")
# every `runs:` entry as its train job will resolve it (method, training and method options: eigs.train.resolve),
# so a typo fails the dry run at once, on one line naming the run, the key and the accepted keys
check_runs(config.get("runs"))

SCENES = config["scenes"]
BUILTIN_SCENES = plan.builtin_scenes(config)
INGESTED_SCENES = plan.ingested_scenes(config)
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
ALL_SCENES = plan.all_scenes(config)


def scene_sfm(scene):
    """The `sfm:` keys of a scene (eigs.plan.scene_sfm)."""
    return plan.scene_sfm(config, scene)


# Each scene's SfM job (eigs.plan.sfm_rule) reads an existing COLMAP model, uses the ground-truth poses of a built-in
# scene (a job of its own, so a dry run shows the skipped COLMAP mapping), or runs COLMAP.
SFM_MODEL_SCENES = plan.sfm_scenes(config, "sfm_model")  # rule sfm_model
SFM_GIVEN_SCENES = plan.sfm_scenes(config, "sfm_given")  # rule sfm_given
SFM_COLMAP_SCENES = plan.sfm_scenes(config, "sfm")  # rule sfm
SFM_SHARED_SCENES = [s for s in SFM_COLMAP_SCENES if plan.sfm_shares_bins(config, s)]  # rule sfm_resample
SFM_BASE_BINS = plan.edi_bins(config)[0]


def sfm_config(wildcards):
    """The scene's `sfm:` keys for `eigs sfm --config` (defaults: eigs.sfm.options.SfmConfig)."""
    return config_json(scene_sfm(wildcards.scene))


def sfm_base(wildcards):
    """Rule sfm_resample: the scene's SfM at the first configured B (eigs.plan.sfm_base_bins)."""
    return f"results/{wildcards.scene}/b{plan.sfm_base_bins(config, wildcards.scene, int(wildcards.bins))}/sfm"


def sfm_model_path(wildcards):
    """Mode model: the scene's COLMAP model directory (an input, so a changed model reruns the job)."""
    return scene_sfm(wildcards.scene)["path"]


# The SfM rule, one definition for the three ways a scene gets its poses (eigs.plan.sfm_rule picks one per scene), the
# same stage and command; its three names differ in `eigs sfm --mode` and the inputs that mode reads (docs/sfm.md):
# - sfm: COLMAP on the latent frames;
# - sfm_given: built-in scenes with ground-truth poses allowed (SFM_GIVEN_SCENES), no COLMAP mapping (triangulation
#   at the given poses for the initial points);
# - sfm_model: scenes whose poses come from an existing COLMAP model (`sfm: {mode: model, path: DIR}`, globally or
#   per scene; SFM_MODEL_SCENES), matched to the views by name; the model is an input, so a changed model reruns it.
# Each name keeps its own shell command, so Snakemake records the same code for it as before.
SFM_LATENTS = {
    "scene": "results/{scene}/scene.h5",
    "edi": "results/{scene}/b{bins}/edi.h5",
    "latent": "results/{scene}/b{bins}/latent",
}


def define_sfm_rule(_name, _scenes, _model, _mode):
    """Define the SfM rule `_name` for `_scenes` with the extra inputs `_model` and the `eigs sfm` flags `_mode` (a
    function, not a loop: the shell command reads `_mode` when the job runs, so each rule needs its own binding)."""

    rule:
        name:
            _name
        input:
            **SFM_LATENTS,
            **_model,
        output:
            directory("results/{scene}/b{bins}/sfm"),
        wildcard_constraints:
            scene=names_regex(_scenes),
            bins=r"\d+",
        params:
            config=sfm_config,
        log:
            "logs/sfm/{scene}_b{bins}.log",
        benchmark:
            "benchmarks/sfm/{scene}_b{bins}.tsv"
        threads: threads_for("sfm")
        resources:
            mem_mb=6000,
        conda:
            "../workflow/envs/eigs.yaml"
        shell:
            "eigs sfm {input.scene} {input.edi} --latent-dir {input.latent} -o {output} --config {params.config} "
            + _mode
            + "--threads {threads} > {log} 2>&1"


def init_config(wildcards):
    """The `init:` section for `eigs init --config` (defaults: eigs.init.options.InitOptions)."""
    return section_json("init")


# --- edi (rules/edi.smk) --------------------------------------------------------------------------------------
EVENT_SCENES = plan.event_scenes(config)  # rule edi
FRAMES_ONLY_SCENES = plan.frames_only_scenes(config)  # rule edi_frames


def edi_bins():
    """The configured bin counts (eigs.plan.edi_bins)."""
    return plan.edi_bins(config)


def edi_config(wildcards):
    """The `edi:` section for `eigs edi --config`, without `bins` (those come from the {bins} wildcard;
    defaults: eigs.edi.options.EdiOptions)."""
    return section_json("edi", exclude=("bins",))


# --- train (rules/train.smk) ----------------------------------------------------------------------------------
RUNS = config.get("runs", {})


def run_bins(run):
    """B of a run (eigs.plan.run_bins)."""
    return plan.run_bins(config, run)


def run_scenes(run):
    """Scenes a run is trained on (eigs.plan.run_scenes)."""
    return plan.run_scenes(config, run)


def run_model_file(run):
    """The model file of a run folder, model.ply or model.npz (eigs.plan.run_model_file)."""
    return plan.run_model_file(config, run)


plan.check(config)  # config errors of the scenes' SfM sections and the runs' scene lists now, not when a rule asks
GAUSSIAN_RUNS = plan.gaussian_runs(config)
FIELD_RUNS = plan.field_runs(config)


RUN_DIR = "results/{scene}/b{bins}/{run}"  # a run folder; its files are named in eigs.artifacts.run


def run_path(name):
    """A file of the run folder (wildcards scene, bins, run) by its name in eigs.artifacts.run."""
    return f"{RUN_DIR}/{name}"


def run_model(wildcards):
    """Input function: the model file of the run folder of `wildcards` (scene, bins, run)."""
    return f"results/{wildcards.scene}/b{wildcards.bins}/{wildcards.run}/{run_model_file(wildcards.run)}"


def train_targets():
    return [f"results/{j.scene}/b{j.bins}/{j.run}/{run_model_file(j.run)}" for j in plan.train_jobs(config)]


def train_config_json(wildcards):
    """The run's method and options as one shell-quoted JSON object for `eigs train --config`."""
    spec = RUNS[wildcards.run]
    if int(wildcards.bins) != run_bins(wildcards.run):
        raise ValueError(f"run {wildcards.run} is configured for B = {run_bins(wildcards.run)}, not {wildcards.bins}")
    values = {"method": spec["method"], **spec.get("options", {})}
    return shlex.quote(json.dumps(values, sort_keys=True, separators=(",", ":")))
