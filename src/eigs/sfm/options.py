"""Options of the ``sfm`` stage: :class:`SfmConfig` (with :class:`ColmapOptions`) holds every default; the config
schema, the rules and the CLI take theirs from here (see ``eigs.util.options``). No heavy imports: the CLI reads it
for its help text."""

from __future__ import annotations

from dataclasses import dataclass, field

from eigs.util.options import Options, choice, run_control

MODES = ("auto", "colmap", "given", "model", "resample")
MATCHERS = ("auto", "exhaustive", "sequential")
DEVICES = ("auto", "cpu", "cuda")


@dataclass(frozen=True)
class ColmapOptions(Options):
    """Options of the COLMAP steps. ``matcher``: auto (exhaustive up to 150 images, else sequential + spatial,
    then exhaustive when the scene is still split into several models) | exhaustive | sequential;
    ``global_mapping``: GLOMAP instead of incremental mapping; ``refine_intrinsics``: let bundle adjustment
    refine the focal length; ``feature_scale``: SIFT upsampling, None for automatic;
    ``device``: auto | cpu | cuda; ``num_threads``: of feature extraction and matching (incremental mapping,
    fixed-pose triangulation and bundle adjustment run on one thread, ``colmap.MAPPER_THREADS``: reproducible);
    ``seed``: of COLMAP's RANSAC and mapper (two-view verification is seeded only when matching runs on several
    threads: ``colmap.verification_seed``). docs/sfm.md, "Reproducibility"."""

    matcher: str = choice("auto", MATCHERS)
    global_mapping: bool = False
    refine_intrinsics: bool = False
    feature_scale: int | None = None
    max_num_features: int = 8192
    sequential_overlap: int | None = run_control(None)  # default: 3 views' worth of latent images
    num_threads: int = run_control(2)
    device: str = choice("auto", DEVICES)
    seed: int = 0
    enhance: bool = run_control(True)  # contrast-stretch dark frames for SIFT
    # Incremental mapper on small (upsampled) frames: reprojection thresholds in original pixels. COLMAP's
    # defaults (4 px; 12 px for absolute pose) suit megapixel images; on 128×96 frames they admitted wrong
    # registrations that folded or bent the orbit (see docs/sfm.md).
    small_max_error_px: float = run_control(1.0)
    small_abs_pose_max_error_px: float = run_control(2.0)


@dataclass(frozen=True)
class SfmConfig(Options):
    """Stage options. ``mode``: auto (given when the scene's latent poses are ground truth and ``allow_given``,
    else colmap) | colmap | given | model (the poses of an existing COLMAP model at ``path``, checked against the
    scene's K within ``intrinsics_tolerance``: eigs.sfm.model) | resample (the latent poses of the scene's SfM at
    another B, ``base``, read at this B's latent times: eigs.sfm.resample); ``share_across_bins``: the workflow
    runs COLMAP once per scene, at the first configured B, and resamples the other B's poses from it (false: one
    COLMAP run per B); ``min_registered_fraction``: of the images given
    to COLMAP, below which the
    stage stops; ``interpolate_unregistered``: fill unregistered latents from registered latents of the same
    view; ``register_test_cameras``: register the ground-truth sharp images into the model (else the Sim(3)-mapped
    ground truth); ``self_check``: COLMAP mode drops the views that leave the camera path and stops when the path
    breaks (eigs.sfm.selfcheck; false: report only). ``keep_work``, ``verbose`` and ``plot`` are run control, not
    config options. The COLMAP options' config keys sit beside these in the `sfm:` section (``colmap`` is nested:
    ``eigs.util.options``)."""

    mode: str = choice("auto", MODES)
    allow_given: bool = True
    path: str | None = None  # model mode: the COLMAP sparse model directory
    intrinsics_tolerance: float = 0.01  # model mode: relative focal, principal point (fraction of the size)
    base: str | None = run_control(None)  # resample mode: the scene's sfm/ directory at another B (--from)
    share_across_bins: bool = True  # workflow: COLMAP scenes run SfM at their first B only (docs/sfm.md)
    min_registered_fraction: float = 0.5
    interpolate_unregistered: bool = True
    register_test_cameras: bool = True
    self_check: bool = True
    keep_work: bool = run_control(False)
    verbose: bool = run_control(False)
    plot: bool = run_control(True)
    colmap: ColmapOptions = field(default_factory=ColmapOptions)

    def problems(self) -> list[str]:
        ok = 0.0 <= self.min_registered_fraction <= 1.0
        return [] if ok else [f"min_registered_fraction must lie in [0, 1], got {self.min_registered_fraction}"]

