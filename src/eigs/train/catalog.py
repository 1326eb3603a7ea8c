"""The method catalog: every training method once, with the facts the workflow, the CLI, the tables and the bench
tools read without importing torch (this module imports none).

An entry names the method's family (``gaussian``: a 3DGS model, ``model.ply``; ``field``: a radiance field,
``model.npz``), the class that trains it (``plugin``, "module:Class", imported only when a run trains), its options
class and recipe (the defaults that make the method, over the class's), what it reads beyond the blurry frames and
its default budget. Adding a method is one :class:`MethodSpec` here and one class with its options beside it
(docs/development.md); another installed package adds its methods through the entry-point group
:data:`ENTRY_POINTS` (``eigs.methods``): each entry point names a :class:`MethodSpec` (or a list of them), loaded when
this module is first imported, so every process sees it (the CLI, the workflow while it plans, the tables).

What a method reads is decided by its recipe (default options), not per run:

- ``needs_events``: its loss reads what only events give the EDI artifact, the event counts and thresholds (an
  event loss) or the EDI latent frames (as targets, or a blur target or latent term built from them). On a scene
  configured with ``events: false`` (``eigs edi --no-events``: every view passed through as sharp) such a run has
  nothing to learn from, so the workflow does not schedule it there. The blur-only deblurring methods read the
  latent poses and EDI's sharp flags, not events: on a frames-only scene every view is sharp, and with their default
  ``sharp_one_render`` they train one render per view as ``3dgs`` does (docs/methods.md);
- ``needs_ground_truth``: it trains on the ground-truth sharp images of the training views (``oracle``);
- ``needs_trajectory``: it reads the latent poses within each exposure (SfM's B + 1 poses per view: as render
  poses, ADE inputs or the start of a learned trajectory), not only each view's reference pose.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from eigs.artifacts.run import MODEL_NPZ, MODEL_PLY
from eigs.errors import EigsError
from eigs.train.config import TrainConfig
from eigs.train.field.options import DeblurNerfOptions, E2NerfOptions, FieldOptions
from eigs.train.gaussian.options import MultiRenderOptions, TrajectoryOptions
from eigs.util.options import Options, parse_options

GAUSSIAN = "gaussian"
FIELD = "field"
ENTRY_POINTS = "eigs.methods"  # the entry-point group of methods from other installed packages


@dataclass(frozen=True)
class Family:
    """A trainer family: the model file of its run folders and its trainer (``"module:Class"`` on the shared loop,
    :mod:`eigs.train.loop`), imported only when a run trains."""

    model_file: str
    trainer: str


FAMILIES = {
    GAUSSIAN: Family(MODEL_PLY, "eigs.train.gaussian.trainer:Trainer"),
    FIELD: Family(MODEL_NPZ, "eigs.train.field.trainer:FieldTrainer"),
}
MODEL_FILES = {name: f.model_file for name, f in FAMILIES.items()}


@dataclass(frozen=True)
class MethodSpec:
    """One method: its name, family, class, options and what it needs (module docstring)."""

    name: str
    family: str  # its trainer family: GAUSSIAN or FIELD (FAMILIES)
    plugin: str  # "module:Class", the class that trains it (a gaussian.methods.Method or field.methods.FieldMethod)
    options: type[Options]  # its options dataclass
    description: str
    recipe: Mapping[str, Any] = field(default_factory=dict)  # its defaults over the options class's
    needs_events: bool = False
    needs_ground_truth: bool = False
    needs_trajectory: bool = False
    steps: int = TrainConfig.steps  # default budget when neither the run's options nor --steps set it
    table1: bool = True  # a row of Table I by default (row key = run name = the method's name; eigs.tables.rows)
    label: str = ""  # its Table I label where the paper has none (eigs.tables.paper); default: its name

    @property
    def model_file(self) -> str:
        """The model file of its run folder: ``model.ply`` (Gaussian) or ``model.npz`` (field)."""
        return FAMILIES[self.family].model_file

    @property
    def trainer(self) -> str:
        """Its family's trainer, ``"module:Class"`` (:data:`FAMILIES`)."""
        return FAMILIES[self.family].trainer

    def defaults(self) -> Options:
        """Its options with nothing set by a run: the options class's defaults with the recipe over them."""
        return parse_options(self.options(), self.recipe, f"method {self.name} recipe")


METHODS: dict[str, MethodSpec] = {}


def register(spec: MethodSpec) -> MethodSpec:
    """Add a method to the catalog (its name must be new)."""
    if not spec.name or spec.name in METHODS:
        raise ValueError(f"method name {spec.name!r} empty or registered twice")
    if spec.family not in MODEL_FILES:
        raise ValueError(f"method {spec.name}: family must be {' or '.join(MODEL_FILES)}, got {spec.family!r}")
    METHODS[spec.name] = spec
    return spec


def load_entry_points(group: str | None = None) -> list[str]:
    """Register the methods that installed packages declare in the entry-point group ``group`` (default
    :data:`ENTRY_POINTS`): each entry point loads a :class:`MethodSpec` or a list of them. Their options classes are
    imported here, so they must import no torch; their ``plugin`` classes only when a run trains. Returns the names
    registered; a broken entry point raises :class:`EigsError` naming it."""
    from importlib.metadata import entry_points

    names = []
    for ep in sorted(entry_points(group=group or ENTRY_POINTS), key=lambda e: e.name):
        where = f"entry point {ep.name} = {ep.value} ({group or ENTRY_POINTS})"
        try:
            loaded = ep.load()
        except Exception as err:  # any error of another package's import: one line naming it
            raise EigsError(where, f"cannot load it ({type(err).__name__}: {err})") from None
        for spec in [loaded] if isinstance(loaded, MethodSpec) else list(loaded):
            if not isinstance(spec, MethodSpec):
                raise EigsError(where, f"expected a MethodSpec or a list of them, got {type(spec).__name__}")
            try:
                register(spec)
            except ValueError as err:
                raise EigsError(where, str(err)) from None
            names.append(spec.name)
    return names


def method(name: str, where: str = "train") -> MethodSpec:
    """The catalog entry of ``name``; an unknown name raises :class:`EigsError` naming the known ones."""
    spec = METHODS.get(name)
    if spec is None:
        raise EigsError(where, f"unknown method {name!r}; known: {', '.join(sorted(METHODS))}")
    return spec


def method_names() -> list[str]:
    """Every method a run may name, sorted."""
    return sorted(METHODS)


def event_methods() -> frozenset[str]:
    """The methods that need a scene's events (``needs_events``)."""
    return frozenset(n for n, s in METHODS.items() if s.needs_events)


def field_methods() -> frozenset[str]:
    """The radiance-field methods (family ``field``: ``model.npz``)."""
    return frozenset(n for n, s in METHODS.items() if s.family == FIELD)


def _load(target: str) -> Any:
    module, _, attr = target.partition(":")
    return getattr(importlib.import_module(module), attr)


def method_class(name: str) -> Any:
    """The class that trains ``name``: imports its plugin module (torch) and returns the class."""
    return _load(method(name).plugin)


def trainer_class(name: str) -> Any:
    """The trainer of ``name``'s family (:data:`FAMILIES`): imports its module (torch) and returns the class."""
    return _load(method(name).trainer)


def _gaussian(name: str, plugin: str, description: str, options: type[Options] = Options, **kw: Any) -> None:
    register(MethodSpec(name, GAUSSIAN, f"eigs.train.gaussian.{plugin}", options, description, **kw))


def _multi(name: str, description: str, **kw: Any) -> None:
    _gaussian(name, "deblur:MultiRender", description, MultiRenderOptions, needs_trajectory=True, **kw)


def _trajectory(name: str, description: str, **kw: Any) -> None:
    _gaussian(name, "camera_motion:TrajectoryMethod", description, TrajectoryOptions, needs_trajectory=True, **kw)


def _field(name: str, cls: str, description: str, options: type[Options] = FieldOptions, **kw: Any) -> None:
    # the field budget: the four runs of a scene one after another (the workflow's 2 threads each) within the tables
    # issue's 15 minutes per scene, from the measured per-step cost (docs/results.md, "The NeRF columns"); the fields
    # are still improving at this budget
    kw.setdefault("steps", 800)
    register(MethodSpec(name, FIELD, f"eigs.train.field.methods:{cls}", options, description, **kw))


# In Table I's order (the default rows of eigs.tables.rows follow it)
_field("nerf", "Nerf", "NeRF (voxel-grid field) on the blurry frames at the reference pose (latent k = 0)")
_field("deblur-nerf", "DeblurNerf",
       "Deblur-NeRF (voxel-grid field): deformable sparse kernel of K rays per pixel from a per-view MLP",
       DeblurNerfOptions)  # fmt: skip
_field("edi-nerf", "EdiNerf", "EDI-NeRF: the field on the EDI latent sharp frames at their latent poses",
       needs_events=True, needs_trajectory=True)  # fmt: skip
_field("e2nerf", "E2Nerf",
       "E²NeRF (voxel-grid field): N+1 latent renders per pixel, blur MSE on their mean + event loss", E2NerfOptions,
       needs_events=True, needs_trajectory=True)  # fmt: skip
_gaussian("3dgs", "methods:Blurry3DGS",
          "3D Gaussian Splatting on the blurry frames at the reference pose (latent k = 0)")  # fmt: skip
_multi("deblurring-gs", "Deblurring-GS: ADE displacements and the blur loss only (Table II (a))",
       recipe={"event_loss": "none", "consistency": False})  # fmt: skip
_multi("deblurring-gs+", "Deblurring-GS+: ADE also predicts rotation and scale changes, blur loss only",
       recipe={"event_loss": "none", "consistency": False, "shape": True})  # fmt: skip
_multi(
    "e2gs",
    "E2GS (w/ est. poses): renders at the N+1 fixed latent poses, blur + E²NeRF-style event loss",
    recipe={"ade": False, "consistency": False, "event_loss": "e2nerf", "lambda_event": 0.02},
    needs_events=True,
)
_trajectory("evagaussians",
            "EvaGaussians (our reading, no public code): cubic B-spline trajectory, blur + event integral losses",
            recipe={"mode": "cubic", "n_control": 4, "n_virtual": 9, "event_loss": "eigs", "lambda_event": 0.1},
            needs_events=True)  # fmt: skip
# BeSplat uses 19 virtual views and a degree-7 Bézier; 17 = 4·4 + 1 puts the N = 4 latent times on virtual views
_trajectory("besplat",
            "BeSplat: a per-view Bézier trajectory, many virtual cameras, L2-normalised log-difference event loss",
            recipe={"mode": "bezier", "n_control": 4, "n_virtual": 17, "event_loss": "normalized",
                    "lambda_event": 2.0}, needs_events=True)  # fmt: skip
_trajectory("bad-gaussians",
            "BAD-Gaussians: a per-view linear SE(3) trajectory, 10 virtual cameras, RGB blur loss only")  # fmt: skip
_multi("eigs", "EiGS: ADE displacements, blur + event-integration + motion-consistency losses", needs_events=True)
_gaussian("edi-3dgs", "methods:Edi3DGS",
          "3DGS on the EDI latent sharp frames at their latent poses (the analogue of EDI-NeRF)",
          needs_events=True, needs_trajectory=True)  # fmt: skip
_gaussian("oracle", "methods:Oracle",
          "upper bound: the ground-truth sharp images of the training views at their reference pose",
          needs_ground_truth=True)  # fmt: skip
# Table II's ablations of eigs (not rows of Table I)
_multi("eigs-b", "EiGS without the motion-consistency loss (Table II (b))", recipe={"consistency": False},
       needs_events=True, table1=False)  # fmt: skip
_multi("eigs-minus", "EiGS without the event loss (Table II Ours−)", recipe={"event_loss": "none"}, table1=False)
# Methods of other installed packages (entry-point group eigs.methods), after the built-in ones
load_entry_points()
