"""Run planning: which jobs a workflow config makes, in one place and without torch.

Plain functions over the config dict (the merged `--configfile` documents): the scenes and how each is made
(built-in, ingested), its EDI rule (`events: false` scenes: `edi_frames`), its SfM rule (COLMAP, given poses, an
existing model), the runs trained on it, each run's B and model file, and :func:`jobs`, every job of the `all`
target by rule and wildcards. rules/common.smk and bench/schedule.py (with it bench/suite_ledger.py) read these,
so the workflow and the schedule simulation cannot disagree. Per-method facts come from the method catalog
(:mod:`eigs.train.catalog`) through :func:`needs_events`, :func:`needs_ground_truth` and :func:`is_field_method`.

Orders are the workflow's: scene lists sorted, a run's `scenes:` list in its own order.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from eigs.artifacts import run as run_folder
from eigs.edi.options import DEFAULT_BINS, EdiOptions
from eigs.evaluate.options import EvaluateOptions
from eigs.ingest import FORMATS
from eigs.init.options import InitOptions
from eigs.sfm.options import SfmConfig
from eigs.train import catalog
from eigs.util.options import check_section

Config = Mapping[str, Any]


# --- per-method facts -----------------------------------------------------------------------------------------
def needs_events(method: str) -> bool:
    """Whether ``method`` reads the scene's events (not scheduled on `events: false` scenes)."""
    return catalog.method(method).needs_events


def needs_ground_truth(method: str) -> bool:
    """Whether ``method`` trains on the ground truth (scheduled only on scenes that have it)."""
    return catalog.method(method).needs_ground_truth


def is_field_method(method: str) -> bool:
    """Whether ``method`` is a radiance-field method (model.npz, rule train_field) rather than Gaussian."""
    return catalog.method(method).family == catalog.FIELD


# --- scenes ---------------------------------------------------------------------------------------------------
def all_scenes(config: Config) -> list[str]:
    return sorted(config["scenes"])


def builtin_scenes(config: Config) -> list[str]:
    """Scenes made by `eigs synth` (rule synth)."""
    return sorted(n for n, s in config["scenes"].items() if "builtin" in s)


def ingested_scenes(config: Config) -> list[str]:
    """Scenes read from a `source:` (rule ingest)."""
    return sorted(n for n, s in config["scenes"].items() if "source" in s)


def simulated_scenes(config: Config) -> list[str]:
    """Built-in scenes written as an E²NeRF real layout first (rule synth_e2nerf_real), then ingested."""
    return sorted(n for n, s in config["scenes"].items() if "simulate" in s)


def scene_uses_events(config: Config, scene: str) -> bool:
    """False for a scene configured with `events: false`: its edi_frames job passes the frames through (`eigs edi
    --no-events`) and no method that needs events trains on it."""
    return config["scenes"][scene].get("events", True) is not False


def event_scenes(config: Config) -> list[str]:
    """Scenes of rule edi."""
    return [s for s in all_scenes(config) if scene_uses_events(config, s)]


def frames_only_scenes(config: Config) -> list[str]:
    """Scenes of rule edi_frames."""
    return [s for s in all_scenes(config) if not scene_uses_events(config, s)]


def scene_hidden_ground_truth(config: Config, scene: str) -> bool:
    """A simulated recording through the real-data path whose ground truth was kept aside and merged at ingestion
    (`simulate:` with `--groundtruth` among its options; rules/synth.smk synth_e2nerf_real, config/davis346.yaml):
    evaluated by the test cameras and BRISQUE both (`eigs evaluate --hidden-ground-truth`)."""
    s = config["scenes"][scene]
    return "simulate" in s and "--groundtruth" in s.get("options", [])


def evaluate_flags(config: Config, scene: str) -> list[str]:
    """`eigs evaluate` flags of a scene from the `evaluate:` config section (unset options keep the CLI's
    defaults), and ``--hidden-ground-truth`` for a simulated recording (BRISQUE beside the test cameras)."""
    e = config.get("evaluate") or {}
    out = ["--path-frames", str(int(e["path_frames"]))] if "path_frames" in e else []
    if "test_pose_iters" in e:
        out += ["--test-pose-iters", str(int(e["test_pose_iters"]))]
    if scene_hidden_ground_truth(config, scene):
        out.append("--hidden-ground-truth")
    return out


def scene_has_ground_truth(config: Config, scene: str) -> bool:
    """Built-in and E²NeRF synthetic scenes, and simulated recordings ingested with `--groundtruth`."""
    s = config["scenes"][scene]
    return "builtin" in s or s.get("format") == "e2nerf-synthetic" or scene_hidden_ground_truth(config, scene)


def edi_bins(config: Config) -> list[int]:
    """The configured bin counts (`edi: bins:`, default [eigs.edi.options.DEFAULT_BINS])."""
    return [int(b) for b in config.get("edi", {}).get("bins", [DEFAULT_BINS])]


# --- sfm ------------------------------------------------------------------------------------------------------
def scene_sfm(config: Config, scene: str) -> dict[str, Any]:
    """The `sfm:` keys of a scene: the global section with the scene's own `sfm:` over it; `{scene}` in `path` is
    the scene name. Mode model without a path is a config error naming the scene."""
    values = {**config.get("sfm", {}), **config["scenes"][scene].get("sfm", {})}
    if "path" in values:
        values["path"] = values["path"].replace("{scene}", scene)
    if values.get("mode") == "model" and not values.get("path"):
        raise ValueError(f"config: scene {scene}: sfm mode model needs `path` (the COLMAP model directory)")
    return values


def sfm_rule(config: Config, scene: str) -> str:
    """The scene's SfM rule: `sfm_model` (`mode: model`), `sfm_given` (a built-in scene with `mode: given`, or `auto`
    with `allow_given`; defaults: eigs.sfm.options.SfmConfig) or `sfm` (COLMAP; ingested scenes keep it and auto mode
    decides from the file, eigs.sfm.run.resolve_mode)."""
    section = scene_sfm(config, scene)
    default = SfmConfig()
    mode = section.get("mode", default.mode)
    if mode == "model":
        return "sfm_model"
    builtin = "builtin" in config["scenes"][scene]
    if builtin and (mode == "given" or (mode == "auto" and section.get("allow_given", default.allow_given))):
        return "sfm_given"
    return "sfm"


def sfm_scenes(config: Config, rule: str) -> list[str]:
    """The scenes whose SfM job is ``rule`` (sfm, sfm_given or sfm_model)."""
    return [s for s in all_scenes(config) if sfm_rule(config, s) == rule]


def sfm_shares_bins(config: Config, scene: str) -> bool:
    """Whether the scene runs SfM at the first configured B only and reads the other B's latent poses from it (rule
    `sfm_resample`, `eigs sfm --mode resample`): a COLMAP scene (rule `sfm`) with `sfm: share_across_bins` (default
    eigs.sfm.options.SfmConfig)."""
    if sfm_rule(config, scene) != "sfm":
        return False
    return bool(scene_sfm(config, scene).get("share_across_bins", SfmConfig().share_across_bins))


def sfm_job_rule(config: Config, scene: str, bins: int) -> str:
    """The rule of the scene's SfM job at ``bins``: `sfm_resample` where :func:`sfm_base_bins` names a base, else
    :func:`sfm_rule`."""
    return "sfm_resample" if sfm_base_bins(config, scene, bins) is not None else sfm_rule(config, scene)


def sfm_base_bins(config: Config, scene: str, bins: int) -> int | None:
    """The B whose SfM the scene's SfM at ``bins`` is resampled from (:func:`sfm_shares_bins`: the first configured
    B, at any other B); None where the job runs its own SfM."""
    base = edi_bins(config)[0]
    return base if bins != base and sfm_shares_bins(config, scene) else None


# --- runs -----------------------------------------------------------------------------------------------------
def runs(config: Config) -> dict[str, Any]:
    return config.get("runs", {})


def run_bins(config: Config, run: str) -> int:
    """B of a run (its `bins:`, else the first configured EDI bins)."""
    return int(runs(config)[run].get("bins", edi_bins(config)[0]))


def run_scenes(config: Config, run: str) -> list[str]:
    """Scenes a run is trained on: its `scenes:` list, else every scene (methods that train on ground truth only on
    scenes that have it; methods that need events only on scenes that have them). A `scenes:` list naming an `events:
    false` scene for a method that needs events is a ValueError."""
    spec = runs(config)[run]
    method = spec["method"]
    if "scenes" in spec:
        scenes = [s for s in spec["scenes"] if s in config["scenes"]]
        frames_only = [s for s in scenes if not scene_uses_events(config, s)]
        if needs_events(method) and frames_only:
            raise ValueError(
                f"config: run {run} (method {method}, which needs events) lists scene(s) "
                f"{', '.join(frames_only)} configured with `events: false`; remove them from its `scenes:` or use a "
                "method that trains on the frames alone"
            )
        return scenes
    if needs_ground_truth(method):
        return [s for s in all_scenes(config) if scene_has_ground_truth(config, s)]
    if needs_events(method):
        return event_scenes(config)
    return all_scenes(config)


def run_model_file(config: Config, run: str) -> str:
    """The model file of a run folder, its method's family's (:attr:`eigs.train.catalog.MethodSpec.model_file`:
    ``model.npz`` for a radiance-field method, else ``model.ply``; :mod:`eigs.artifacts.run`)."""
    return catalog.method(runs(config)[run]["method"]).model_file


def gaussian_runs(config: Config) -> list[str]:
    """Runs of rule train."""
    return sorted(r for r in runs(config) if run_model_file(config, r) == run_folder.MODEL_PLY)


def field_runs(config: Config) -> list[str]:
    """Runs of rule train_field."""
    return sorted(r for r in runs(config) if run_model_file(config, r) == run_folder.MODEL_NPZ)


def check_sections(config: Config) -> None:
    """The stage sections (``edi:``, ``sfm:`` globally and per scene, ``init:``, ``evaluate:``) through the validator
    their CLIs use (``Options.from_dict`` of :mod:`eigs.util.options`: keys, types, accepted values, checks), before
    the schema, so that a mistake fails the dry run on one line naming the key and the accepted keys or values. The
    `edi:` section's ``bins`` is a list of B, each checked as the option ``bins``."""
    edi = config.get("edi")
    if isinstance(edi, Mapping):
        bins = edi.get("bins", [])
        for b in bins if isinstance(bins, list) else [bins]:
            check_section("config: edi: bins", {"bins": b}, EdiOptions)
        edi = {k: v for k, v in edi.items() if k != "bins"}
    check_section("config: edi", edi, EdiOptions)
    check_section("config: sfm", config.get("sfm"), SfmConfig)
    check_section("config: init", config.get("init"), InitOptions)
    check_section("config: evaluate", config.get("evaluate"), EvaluateOptions)
    scenes = config.get("scenes")
    for scene, spec in (scenes.items() if isinstance(scenes, Mapping) else ()):
        if isinstance(spec, Mapping):
            check_section(f"config: scene {scene}: sfm", spec.get("sfm"), SfmConfig)


def check(config: Config) -> None:
    """Raise the config errors of the scenes' formats and SfM sections and the runs' scene lists now, not when a
    rule asks."""
    for scene in ingested_scenes(config):
        fmt = config["scenes"][scene].get("format")
        if fmt not in FORMATS:
            accepted = ", ".join(FORMATS)
            raise ValueError(f"config: scene {scene}: format {fmt!r} is not one `eigs ingest` reads ({accepted})")
        check_ingest_options(scene, fmt, config["scenes"][scene].get("options", []))
    for scene in all_scenes(config):
        sfm_rule(config, scene)
    for run in runs(config):
        run_scenes(config, run)


def check_ingest_options(scene: str, fmt: str, options: list) -> None:
    """A scene's `options:` (the `eigs ingest` flags its rule appends) through the ingest CLI's own parser and
    option checks, as the rule gives them (``--format F --name SCENE OPTIONS SOURCE -o OUT``): an unknown
    flag, a missing or malformed value fails the dry run on one line naming the scene."""
    import argparse

    from eigs.errors import EigsError
    from eigs.ingest.cli import add_arguments, options_from_args

    class Parser(argparse.ArgumentParser):
        def error(self, message: str):  # argparse would print usage and exit
            raise ValueError(message)

    where = f"config: scene {scene}: options"
    if not isinstance(options, list):
        raise ValueError(f"{where}: expected a list of `eigs ingest` flags and values, got {options!r}")
    parser = Parser(prog="eigs ingest", add_help=False)
    add_arguments(parser)
    argv = ["--format", fmt, "--name", scene, "-o", "OUT.h5", *(str(o) for o in options), "--", "SOURCE"]
    try:
        args, extra = parser.parse_known_args(argv)
        stray = [a for a in extra if a != "SOURCE"] + ([args.source] if args.source != "SOURCE" else [])
        if stray:
            raise ValueError(f"not `eigs ingest` flags or their values: {' '.join(stray)}")
        options_from_args(args)
    except (ValueError, EigsError) as err:
        raise ValueError(f"{where}: {err}") from None


# --- jobs -----------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Job:
    """One job of the `all` target: its rule and wildcards (empty where the rule has none)."""

    rule: str
    scene: str = ""
    bins: int | None = None
    run: str = ""

    def __str__(self) -> str:
        """As a dry run names it: ``train scene=chair bins=4 run=eigs``."""
        wildcards = [("scene", self.scene), ("bins", self.bins), ("run", self.run)]
        return " ".join([self.rule, *(f"{k}={v}" for k, v in wildcards if v not in ("", None))])


def train_jobs(config: Config) -> list[Job]:
    """The training jobs (rule train or train_field), runs sorted, each over its scenes; rule evaluate has one job
    per training job, with the same wildcards."""
    out = []
    for run in sorted(runs(config)):
        rule = "train_field" if is_field_method(runs(config)[run]["method"]) else "train"
        out += [Job(rule, scene, run_bins(config, run), run) for scene in run_scenes(config, run)]
    return out


def video_runs(config: Config) -> list[str]:
    """The runs an orbit video shows, in order: `video: runs:` (each must be a `runs:` entry), else the runs of
    Table I's rows eigs.view.video.VideoOptions.table1_rows."""
    from eigs.tables.rows import table_rows
    from eigs.view.video import VideoOptions

    given = config.get("video", {}).get("runs")
    if given is not None:
        unknown = [r for r in given if r not in runs(config)]
        if unknown:
            raise ValueError(f"config: video: runs {', '.join(unknown)} are not in `runs:`")
        return list(dict.fromkeys(given))
    table1 = table_rows(config.get("tables"))["table1"]
    return list(dict.fromkeys(table1[k] for k in VideoOptions().table1_rows if table1.get(k) in runs(config)))


def video_scenes(config: Config) -> list[str]:
    """Scenes with an orbit video: every scene a video run is trained on."""
    return sorted({s for r in video_runs(config) for s in run_scenes(config, r)})


def jobs(config: Config) -> list[Job]:
    """Every job of the `all` target (what `snakemake -n all` schedules in an empty directory), grouped by stage."""
    scenes = all_scenes(config)
    bins = edi_bins(config)
    out = [Job("resources")]
    out += [Job("synth", s) for s in builtin_scenes(config)]
    out += [Job("synth_e2nerf_real", s) for s in simulated_scenes(config)]
    out += [Job("ingest", s) for s in ingested_scenes(config)]
    for s in scenes:
        edi = "edi" if scene_uses_events(config, s) else "edi_frames"
        out += [Job(rule, s, b) for b in bins for rule in (edi, sfm_job_rule(config, s, b), "init")]
    training = train_jobs(config)
    out += training + [Job("evaluate", j.scene, j.bins, j.run) for j in training]
    out += [Job("video", s) for s in video_scenes(config)]
    return [*out, Job("tables"), Job("figures")]
