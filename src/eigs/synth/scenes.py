"""The built-in synthetic scenes and their parameters.

Six benchmark scenes mirror the six E²NeRF synthetic scenes in count and variety (chair, ficus, hotdog, lego,
materials, mic → blocks, chair, tree, dish, spheres, drums), plus the tiny CI scene ``toy``. Each scene is a
fixed arrangement of textured primitives (:mod:`eigs.synth.raycast`) plus per-scene defaults (field of
view, orbit, shake strength, background); every parameter in :data:`DEFAULTS` can be overridden
(``--config`` / ``--overrides``). The seed drives the shake, the sensor mismatch and the noise; the geometry
is fixed per scene.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from eigs.errors import EigsError
from eigs.synth.blur import BLUR_SYNTHESIS_CHOICES, E2NERF_RENDERS
from eigs.synth.frame_noise import FRAME_NOISE_CHOICES
from eigs.synth.raycast import Box, Cylinder, Lighting, Material, Patchwork, Primitive, Sphere, rotation

# ---------------------------------------------------------------------------------------------------------
# Parameters: global defaults (every scene), each scene may change some; users override any of them.
DEFAULTS: dict[str, Any] = {
    # image and views
    "width": 128,
    "height": 96,
    "fov_deg": 60.0,  # horizontal field of view (narrower views leave SfM a rotation/translation ambiguity)
    "n_train": 24,
    "n_novel": 12,
    # time base (µs)
    "exposure_us": 100_000,
    "period_us": 200_000,  # exposure start to next exposure start
    "lead_us": 10_000,  # recording starts this long before the first exposure
    "subframes": 80,  # rendered sub-frame intervals per exposure (subframes + 1 frames)
    "gap_subframes": 40,
    "lead_subframes": 2,
    "n_bins": 4,  # B: latent poses at B + 1 times per exposure
    # orbit (scene units, degrees)
    "orbit_radius": 3.2,
    "elevation_min": 15.0,
    "elevation_max": 45.0,
    # shake
    "shake": 1.0,  # strength multiplier (0 = no shake)
    "shake_rot_deg": 1.6,  # RMS rotation per pitch/yaw axis at strength 1 (roll: half)
    "shake_trans": 0.025,  # RMS translation per axis at strength 1 (scene units)
    "shake_fmin_hz": 2.0,
    "shake_fmax_hz": 12.0,
    "still_views": 0.0,  # fraction of training views held still during their exposure (sharp frame, noise events)
    # renderer
    "supersample": 2,
    "texture_size": 128,
    "camera_response": "linear",  # or "srgb": how linear intensity is encoded in the uint8 frames
    "light_level": 1.0,  # scene illumination multiplier on the linear render (< 1: low light; frames and events)
    "frame_noise": "none",  # APS noise on the blurry frames (eigs.synth.frame_noise: none | davis346)
    "blur_synthesis": "average",  # blurry frame: mean of all sub-frames, or E²NeRF's 17 renders (eigs.synth.blur)
    # event sensor
    "contrast_threshold": 0.2,
    "threshold_pos": None,
    "threshold_neg": None,
    "threshold_sigma": 0.03,
    "refractory_us": 100.0,
    "shot_noise_hz": 0.05,
    "leak_rate_hz": 0.05,
    "leak_rate_cov_decades": 0.0,  # per-pixel log-normal spread of the leak rate (decades, v2e)
    "leak_random_phase": False,  # start each pixel's leak at a random phase (a sensor already running)
    "shot_noise_inten_factor": 1.0,  # shot-noise rate × (1 + (f − 1)·inten01) (v2e: 0.25); 1: uniform
    "hot_pixel_fraction": 0.0,  # fraction of pixels that fire on their own
    "hot_pixel_rate_hz": 0.0,  # their rate (Poisson, random polarity)
    "reset_at_exposure": False,  # reset every pixel's reference at each exposure start (tests)
    "seed": 0,
    "preset": None,  # a named sensor/capture preset (PRESETS), applied over the scene's defaults
}

# Named presets: a camera and capture setting applied over a scene's own defaults and under the user's overrides
# (any built-in scene). Every value's source is in PRESET_SOURCES and docs/synthetic.md ("Presets").
PRESETS: dict[str, dict[str, Any]] = {
    "davis346": {
        "width": 346,
        "height": 260,
        "n_train": 30,
        "n_novel": 15,
        "exposure_us": 100_000,
        "period_us": 1_000_000,
        "gap_subframes": 40,
        "light_level": 0.4,
        "contrast_threshold": 0.19,
        "threshold_pos": 0.21,
        "threshold_neg": 0.17,
        "threshold_sigma": 0.05,
        "refractory_us": 500.0,
        "shot_noise_hz": 5.0,
        "shot_noise_inten_factor": 0.25,
        "leak_rate_hz": 0.1,
        "leak_rate_cov_decades": 0.1,
        "leak_random_phase": True,
        "hot_pixel_fraction": 0.0025,
        "hot_pixel_rate_hz": 29.0,
    },
}
_V2E = "SensorsINI/v2e@b0ae3bcb6eec237e995d53f6d78f867d4676ffaa"
PRESET_SOURCES: dict[str, dict[str, str]] = {
    "davis346": {
        "width": "DAVIS346 sensor 346×260 (iniVation libcaer davis.h, DAVIS346 chip ids; E²NeRF paper §5.1)",
        "height": "as width",
        "n_train": "E²NeRF paper §5.1: 30 blurry views per real scene",
        "n_novel": "ours: held-out views for scoring (the real E²NeRF scenes have none)",
        "exposure_us": "E²NeRF paper §5.1: APS exposure 100 ms",
        "period_us": "E²NeRF real preprocessing keeps every 10th APS frame (data-preprocessing.py), frames ≥ 100 ms "
                     "apart at a 100 ms exposure: ≥ 1 s between views",
        "gap_subframes": "ours: keeps the gap steps at 22.5 ms (period − exposure must divide)",
        "light_level": "[assumed] E²NeRF paper §5.1 records at 5–100 lux but states no frame brightness; 0.4 gives "
                       "mean blurry frames of 0.05–0.07 linear (13–18 of 255) on the six scenes (davis346_lab, a lit "
                       "lab at 4.8 ms: 0.20)",
        "contrast_threshold": "mean of threshold_pos and threshold_neg (the scene's nominal C)",
        "threshold_pos": f"v2e EventEmulator docstring, nominal ON threshold 0.21 ({_V2E} v2ecore/emulator.py)",
        "threshold_neg": "v2e EventEmulator docstring, nominal OFF threshold 0.17 (same file)",
        "threshold_sigma": "v2e dvs_params 'noisy' preset: sigma_thres 0.05 (emulator.py set_dvs_params)",
        "refractory_us": f"v2e CLI default --refractory_period 0.5 ms ({_V2E} v2ecore/v2e_args.py)",
        "shot_noise_hz": "v2e dvs_params 'noisy' preset: shot_noise_rate_hz 5 (low light; the CLI default 0.001 Hz "
                         "is 'for good lighting')",
        "shot_noise_inten_factor": "v2e SHOT_NOISE_INTEN_FACTOR 0.25 with inten01 = (DN + 20)/275 "
                                   "(emulator.py, emulator_utils.py generate_shot_noise, rescale_intensity_frame)",
        "leak_rate_hz": "v2e dvs_params 'noisy' preset and EventEmulator default: leak_rate_hz 0.1",
        "leak_rate_cov_decades": "v2e --noise_rate_cov_decades default 0.1 (log-normal per-pixel leak rate)",
        "leak_random_phase": "[assumed] steady state of a sensor that was already running (v2e's earlier code set a "
                             "random initial leak offset; emulator.py keeps it commented out)",
        "hot_pixel_fraction": "measured on ../shared/data/real/davis346_lab (aestream sample, DAVIS346): 18 of 7,230 "
                              "still pixels fire ≥ 3 times in 0.13 s (an upper bound: flicker may add to it)",
        "hot_pixel_rate_hz": "measured there: those pixels fire at 29 Hz on average, both polarities",
    },
}

_INT_KEYS = {
    "width", "height", "n_train", "n_novel", "exposure_us", "period_us", "lead_us", "subframes", "gap_subframes",
    "lead_subframes", "n_bins", "supersample", "texture_size", "seed",
}
_OPTIONAL_FLOAT_KEYS = {"threshold_pos", "threshold_neg"}
_BOOL_KEYS = {"reset_at_exposure", "leak_random_phase"}
_STR_KEYS = {"camera_response": ("linear", "srgb"), "frame_noise": FRAME_NOISE_CHOICES,
             "blur_synthesis": BLUR_SYNTHESIS_CHOICES}
_OPTIONAL_STR_KEYS = {"preset": tuple(PRESETS)}


@dataclass
class SceneSpec:
    """A built-in scene: ``build()`` returns its primitives; ``params`` overrides :data:`DEFAULTS`."""

    name: str
    description: str
    build: Callable[[], list[Primitive]]
    background: tuple[float, float, float]
    params: dict[str, Any] = field(default_factory=dict)
    target: tuple[float, float, float] = (0.0, 0.0, 0.0)
    lighting: Lighting = field(default_factory=Lighting)


def M(texture: str, tint=(1.0, 1.0, 1.0), tile: float = 1.0) -> Material:
    return Material(texture, tuple(float(v) for v in tint), float(tile))


def _ground(size: float, z: float, material: Material, thickness: float = 0.1) -> Box:
    return Box((0.0, 0.0, z - thickness), material, half=(size, size, thickness))


# Photographs that are not periodic (bricks, grass blades and text lines repeat; a colour wheel has no corners).
_ENV_PHOTOS = ("astronaut", "camera", "chelsea", "coffee", "coins", "hubble", "ihc", "moon", "retina", "rocket",
               "gravel")  # fmt: skip


def _environment(z: float, seed: int, half: float = 7.5, n: int = 6, wall_height: float = 5.0) -> list[Primitive]:
    """A room around the scene: an n × n patchwork floor (top at height ``z``, ±``half``) and 8 walls on the
    octagon of inradius ``half``. Every patch and wall shows a different window of a different photograph (no
    texture repeats anywhere, no mirror seams), with its own tint, so any two places in the room look different:
    SfM gets correspondences at all depths around the object, and no ambiguous ones."""
    rng = np.random.default_rng(seed)  # fixed layout per scene, independent of the user's seed
    windows = [(name, (x0, y0, 0.5)) for name in _ENV_PHOTOS for x0 in (0.0, 0.5) for y0 in (0.0, 0.5)]
    order = rng.permutation(len(windows))
    prims: list[Primitive] = []

    def material(i: int, tile: float, offset: tuple[float, float]) -> Material:
        name, crop = windows[order[i % len(windows)]]
        tint = tuple(float(c) for c in rng.uniform(0.45, 1.0, 3))
        return Material(name, tint, tile, crop, offset)

    side = 2 * half / n
    cells = tuple(material(i, side / 0.9, (0.0, 0.0)) for i in range(n * n))  # 90 % of each window visible
    prims.append(Patchwork((0.0, 0.0, z), cells[0], half=half, cells=cells))
    width = 2 * half * math.tan(math.pi / 8)
    for k in range(8):
        phi = 2 * math.pi * k / 8
        c = ((half + 0.05) * math.cos(phi), (half + 0.05) * math.sin(phi), z + wall_height / 2)
        # local y points along the radius: the inner face is axis 1, mapping (z, x)/tile + (0.37, 0.21)
        rot = rotation((0, 0, 1), math.degrees(phi) - 90.0)
        prims.append(Box(c, material(n * n + k, width / 0.9, (0.13, 0.29)), rot=rot,
                         half=(width / 2 + 0.05, 0.05, wall_height / 2)))
    return prims


# ---------------------------------------------------------------------------------------------------------
# Geometry. World: z up, objects within about ±1.3 of the origin (like the NeRF synthetic scenes).
def _toy() -> list[Primitive]:
    return [
        _ground(1.6, -0.6, M("gravel", (0.9, 0.8, 0.7), 1.2)),
        Box((-0.3, -0.2, -0.1), M("astronaut", tile=1.0), rot=rotation((0, 0, 1), 25), half=(0.45, 0.45, 0.5)),
        Sphere((0.55, 0.45, -0.2), M("coffee", tile=1.5), radius=0.4),
    ]


def _blocks() -> list[Primitive]:
    rz = lambda a: rotation((0, 0, 1), a)  # noqa: E731
    return [
        *_environment(-0.83, 11),
        Box((0.0, 0.0, -0.75), M("gravel", (0.6, 0.6, 0.65), 1.0), half=(1.2, 0.9, 0.08)),
        Box((-0.45, -0.2, -0.4), M("brick", (0.9, 0.45, 0.3), 0.6), rot=rz(10), half=(0.45, 0.35, 0.28)),
        Box((0.5, 0.25, -0.45), M("rocket", tile=0.9), rot=rz(-20), half=(0.35, 0.4, 0.22)),
        Box((-0.3, -0.1, 0.1), M("colorwheel", tile=0.8), rot=rz(35), half=(0.3, 0.25, 0.25)),
        Box((0.4, 0.2, 0.0), M("chelsea", tile=0.8), rot=rz(5), half=(0.22, 0.3, 0.22)),
        Box((0.05, 0.05, 0.55), M("brick", (0.35, 0.5, 0.85), 0.5), rot=rz(-15), half=(0.35, 0.18, 0.2)),
        Cylinder((0.75, -0.55, -0.35), M("hubble", tile=0.6), radius=0.2, half_height=0.35),
        Cylinder((-0.8, 0.5, -0.45), M("coins", (1.0, 0.85, 0.4), 0.5), radius=0.25, half_height=0.25),
        Sphere((0.05, 0.05, 0.95), M("ihc", tile=0.5), radius=0.2),
    ]


def _chair() -> list[Primitive]:
    wood = M("gravel", (0.75, 0.5, 0.3), 0.7)
    legs = [
        Box((sx * 0.45, sy * 0.42, -0.55), wood, half=(0.06, 0.06, 0.45))
        for sx in (-1, 1)
        for sy in (-1, 1)
    ]
    return [
        *_environment(-1.0, 12),
        *legs,
        Box((0.0, 0.0, -0.05), wood, half=(0.55, 0.5, 0.06)),
        Box((0.0, 0.0, 0.06), M("astronaut", tile=1.1), half=(0.5, 0.45, 0.05)),
        Box((-0.5, 0.0, 0.55), M("chelsea", tile=1.0), rot=rotation((0, 1, 0), -8), half=(0.06, 0.5, 0.55)),
        Box((-0.5, 0.0, 1.12), wood, half=(0.08, 0.55, 0.06)),
    ]


def _tree() -> list[Primitive]:
    rng = np.random.default_rng(1234)  # fixed layout, independent of the user's seed
    leaves = []
    for _ in range(22):
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        c = np.array([0.0, 0.0, 0.55]) + u * np.array([0.6, 0.6, 0.45]) * rng.uniform(0.4, 1.0)
        tint = (rng.uniform(0.4, 0.7), rng.uniform(0.8, 1.0), rng.uniform(0.3, 0.5))
        leaves.append(Sphere(tuple(c), M("grass", tint, 0.5), radius=float(rng.uniform(0.12, 0.24))))
    return [
        *_environment(-1.1, 13),
        Cylinder((0.0, 0.0, -0.85), M("brick", (0.85, 0.5, 0.35), 0.5), radius=0.35, half_height=0.25),
        Cylinder((0.0, 0.0, -0.6), M("moon", (0.4, 0.3, 0.2), 0.4), radius=0.3, half_height=0.02),
        Cylinder((0.0, 0.0, -0.05), M("gravel", (0.5, 0.35, 0.2), 0.4), radius=0.05, half_height=0.6),
        Cylinder((0.2, 0.0, 0.3), M("gravel", (0.5, 0.35, 0.2), 0.4), rot=rotation((0, 1, 0), 40), radius=0.035,
                 half_height=0.3),
        *leaves,
    ]


def _dish() -> list[Primitive]:
    horiz = rotation((0, 1, 0), 90)
    return [
        *_environment(-0.35, 14),
        Cylinder((0.0, 0.0, -0.3), M("moon", (0.9, 0.9, 0.95), 1.5), radius=1.0, half_height=0.04),
        Cylinder((0.0, 0.0, -0.24), M("coins", (0.95, 0.95, 1.0), 0.8), radius=0.85, half_height=0.02),
        # two "buns" and "sausages"
        Box((0.0, -0.28, -0.12), M("coffee", tile=0.6), rot=rotation((0, 0, 1), 3), half=(0.65, 0.16, 0.1)),
        Box((0.0, 0.28, -0.12), M("coffee", tile=0.6), rot=rotation((0, 0, 1), -4), half=(0.65, 0.16, 0.1)),
        Cylinder((0.0, -0.28, 0.02), M("rocket", (1.0, 0.6, 0.45), 0.4), rot=horiz, radius=0.08, half_height=0.6),
        Cylinder((0.0, 0.28, 0.02), M("rocket", (1.0, 0.6, 0.45), 0.4), rot=horiz, radius=0.08, half_height=0.6),
        Sphere((0.6, -0.28, 0.02), M("chelsea", (1.0, 0.7, 0.5), 0.3), radius=0.08),
        Sphere((-0.6, -0.28, 0.02), M("chelsea", (1.0, 0.7, 0.5), 0.3), radius=0.08),
        Sphere((0.6, 0.28, 0.02), M("chelsea", (1.0, 0.7, 0.5), 0.3), radius=0.08),
        Sphere((-0.6, 0.28, 0.02), M("chelsea", (1.0, 0.7, 0.5), 0.3), radius=0.08),
    ]


def _spheres() -> list[Primitive]:
    textures = ["astronaut", "coffee", "chelsea", "rocket", "hubble", "retina", "ihc", "colorwheel", "brick"]
    tints = [(1, 1, 1)] * 8 + [(0.9, 0.5, 0.35)]
    prims: list[Primitive] = _environment(-0.45, 15)
    for k, (tex, tint) in enumerate(zip(textures, tints, strict=True)):
        i, j = divmod(k, 3)
        prims.append(Sphere(((i - 1) * 0.85, (j - 1) * 0.85, -0.1), M(tex, tint, 1.0), radius=0.34))
    return prims


def _drums() -> list[Primitive]:
    def tilt(ax: float, ay: float) -> np.ndarray:
        return rotation((1, 0, 0), ax) @ rotation((0, 1, 0), ay)

    metal = M("moon", (1.0, 0.85, 0.45), 0.5)
    return [
        *_environment(-1.0, 16),
        Cylinder((0.0, 0.4, -0.55), M("hubble", tile=1.2), rot=rotation((1, 0, 0), 90), radius=0.5,
                 half_height=0.28),  # bass drum
        Cylinder((-0.55, -0.25, -0.2), M("retina", tile=0.6), rot=tilt(10, 0), radius=0.3, half_height=0.14),
        Cylinder((0.55, -0.25, -0.2), M("ihc", tile=0.6), rot=tilt(-10, 5), radius=0.27, half_height=0.13),
        Cylinder((0.0, -0.6, -0.45), M("rocket", tile=0.8), radius=0.3, half_height=0.22),
        Cylinder((-0.9, 0.2, 0.35), metal, rot=tilt(15, 10), radius=0.45, half_height=0.012),  # cymbals
        Cylinder((0.9, 0.3, 0.25), metal, rot=tilt(-10, -15), radius=0.38, half_height=0.012),
        Cylinder((-0.9, 0.2, -0.32), M("gravel", (0.3, 0.3, 0.3), 0.3), radius=0.025, half_height=0.68),
        Cylinder((0.9, 0.3, -0.37), M("gravel", (0.3, 0.3, 0.3), 0.3), radius=0.025, half_height=0.63),
        Cylinder((-0.55, -0.25, -0.65), M("gravel", (0.3, 0.3, 0.3), 0.3), radius=0.025, half_height=0.35),
        Cylinder((0.55, -0.25, -0.65), M("gravel", (0.3, 0.3, 0.3), 0.3), radius=0.025, half_height=0.35),
    ]


SCENES: dict[str, SceneSpec] = {
    "toy": SceneSpec(
        "toy", "CI scene: a textured box and a sphere on gravel (64×48, 8 + 4 views)", _toy, (0.08, 0.08, 0.1),
        {"width": 64, "height": 48, "n_train": 8, "n_novel": 4, "fov_deg": 40.0, "orbit_radius": 4.0,
         "shake_rot_deg": 1.0, "shake_trans": 0.02},
    ),
    "blocks": SceneSpec(
        "blocks", "stacked textured blocks, cylinders and a ball on a plate (≈ lego)", _blocks, (0.05, 0.05, 0.06),
        {"shake_rot_deg": 1.6},
    ),
    "chair": SceneSpec(
        "chair", "a wooden chair with a photo cushion and back on a brick floor (≈ chair)", _chair,
        (0.1, 0.1, 0.12), {"orbit_radius": 3.45, "elevation_min": 10.0, "elevation_max": 40.0,
                           "shake_rot_deg": 1.45},
        target=(0.0, 0.0, 0.0),
    ),
    "tree": SceneSpec(
        "tree", "a potted tree: thin trunk, many leaf spheres, wide floor, large depth range (≈ ficus)", _tree,
        (0.12, 0.14, 0.18), {"orbit_radius": 3.7, "elevation_min": 8.0, "elevation_max": 35.0,
                             "shake_rot_deg": 1.9},
    ),
    "dish": SceneSpec(
        "dish", "a plate with two buns and sausages seen from close up (≈ hotdog)", _dish, (0.04, 0.04, 0.04),
        {"orbit_radius": 2.6, "elevation_min": 25.0, "elevation_max": 60.0, "shake_rot_deg": 1.45,
         "shake_trans": 0.019},
        target=(0.0, 0.0, -0.15),
    ),
    "spheres": SceneSpec(
        "spheres", "a 3×3 grid of photo-textured spheres (≈ materials)", _spheres, (0.15, 0.15, 0.15),
        {"orbit_radius": 3.4, "elevation_min": 20.0, "elevation_max": 50.0, "shake_rot_deg": 1.75},
    ),
    "drums": SceneSpec(
        "drums", "a drum kit: drums, thin cymbals and stands (≈ mic/drums)", _drums, (0.03, 0.03, 0.05),
        {"orbit_radius": 3.5, "elevation_min": 10.0, "elevation_max": 40.0, "shake_rot_deg": 1.6},
    ),
}
SCENE_NAMES: tuple[str, ...] = tuple(SCENES)


def get_spec(name: str) -> SceneSpec:
    if name not in SCENES:
        raise EigsError(None, f"unknown built-in scene {name!r}; available: {', '.join(SCENE_NAMES)}")
    return SCENES[name]


def _coerce(key: str, value: Any, where: str) -> Any:
    if key in _BOOL_KEYS:
        if not isinstance(value, bool):
            raise EigsError(where, f"{key} must be true or false, got {value!r}")
        return value
    if key in _OPTIONAL_STR_KEYS:
        if value is not None and value not in _OPTIONAL_STR_KEYS[key]:
            raise EigsError(where, f"{key} must be null or one of {_OPTIONAL_STR_KEYS[key]}, got {value!r}")
        return value
    if key in _STR_KEYS:
        if value not in _STR_KEYS[key]:
            raise EigsError(where, f"{key} must be one of {_STR_KEYS[key]}, got {value!r}")
        return value
    if key in _OPTIONAL_FLOAT_KEYS and value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise EigsError(where, f"{key} must be a number, got {value!r}")
    if key in _INT_KEYS:
        if float(value) != int(value):
            raise EigsError(where, f"{key} must be an integer, got {value!r}")
        return int(value)
    if not math.isfinite(float(value)):
        raise EigsError(where, f"{key} must be finite, got {value!r}")
    return float(value)


def resolve_params(name: str, *layers: tuple[str, dict[str, Any] | None]) -> dict[str, Any]:
    """Parameters of scene ``name``: :data:`DEFAULTS` ← the scene's defaults ← the preset (the last ``preset`` any
    layer names, :data:`PRESETS`) ← each ``(where, overrides)`` layer in order (``where`` names the source in error
    messages). Unknown keys and bad values raise :class:`EigsError`."""
    spec = get_spec(name)
    params = {**DEFAULTS, **spec.params}
    for where, layer in layers:
        if layer and not isinstance(layer, dict):
            raise EigsError(where, f"overrides must be a mapping of parameter → value, got {type(layer).__name__}")
        if layer and "preset" in layer:
            params["preset"] = _coerce("preset", layer["preset"], where)
    if params["preset"] is not None:
        params.update(PRESETS[params["preset"]])
    for where, layer in layers:
        if not layer:
            continue
        unknown = sorted(set(layer) - set(DEFAULTS))
        if unknown:
            raise EigsError(where, f"unknown parameter(s) {', '.join(map(repr, unknown))}; known: "
                            f"{', '.join(sorted(DEFAULTS))}")
        for k, v in layer.items():
            params[k] = _coerce(k, v, where)
    check_params(params, where=" / ".join(w for w, layer in layers if layer) or name)
    return params


def check_params(p: dict[str, Any], where: str = "parameters") -> None:
    """Range and consistency checks (divisibility of the time base, positivity...)."""

    def need(cond: bool, msg: str) -> None:
        if not cond:
            raise EigsError(where, msg)

    for k in ("width", "height", "n_train", "subframes", "gap_subframes", "lead_subframes", "n_bins", "supersample"):
        need(p[k] >= 1, f"{k} must be ≥ 1, got {p[k]}")
    need(p["width"] <= 4096 and p["height"] <= 4096, "width and height must be ≤ 4096")
    need(p["n_novel"] >= 0, f"n_novel must be ≥ 0, got {p['n_novel']}")
    need(p["texture_size"] >= 8, f"texture_size must be ≥ 8, got {p['texture_size']}")
    need(0 < p["fov_deg"] < 170, f"fov_deg must lie in (0, 170), got {p['fov_deg']}")
    need(p["exposure_us"] > 0, f"exposure_us must be > 0, got {p['exposure_us']}")
    need(p["period_us"] > p["exposure_us"], "period_us must exceed exposure_us (a gap between exposures)")
    need(p["lead_us"] >= 0, f"lead_us must be ≥ 0, got {p['lead_us']}")
    need(p["subframes"] % p["n_bins"] == 0, f"subframes ({p['subframes']}) must be a multiple of n_bins "
         f"({p['n_bins']}) so latent times are sub-frame times")
    steps = E2NERF_RENDERS - 1
    need(p["blur_synthesis"] != "e2nerf" or p["subframes"] % steps == 0, f"blur_synthesis e2nerf needs subframes "
         f"a multiple of {steps} (its {E2NERF_RENDERS} renders are sub-frames), got {p['subframes']}")
    need(p["exposure_us"] % p["subframes"] == 0, f"exposure_us ({p['exposure_us']}) must be a multiple of "
         f"subframes ({p['subframes']}) so sub-frame times are whole µs")
    gap = p["period_us"] - p["exposure_us"]
    need(gap % p["gap_subframes"] == 0, f"period_us − exposure_us ({gap}) must be a multiple of gap_subframes "
         f"({p['gap_subframes']})")
    need(p["lead_us"] % p["lead_subframes"] == 0, f"lead_us ({p['lead_us']}) must be a multiple of "
         f"lead_subframes ({p['lead_subframes']})")
    need(p["orbit_radius"] > 0, "orbit_radius must be > 0")
    need(-85 <= p["elevation_min"] <= p["elevation_max"] <= 85, "need −85 ≤ elevation_min ≤ elevation_max ≤ 85")
    for k in ("shake", "shake_rot_deg", "shake_trans"):
        need(p[k] >= 0, f"{k} must be ≥ 0, got {p[k]}")
    need(0 < p["shake_fmin_hz"] <= p["shake_fmax_hz"], "need 0 < shake_fmin_hz ≤ shake_fmax_hz")
    need(0 <= p["still_views"] <= 1, f"still_views must lie in [0, 1] (a fraction of the training views), got "
         f"{p['still_views']}")
    need(p["seed"] >= 0, f"seed must be ≥ 0, got {p['seed']}")
    need(p["contrast_threshold"] > 0, "contrast_threshold must be > 0")
    for k in ("threshold_pos", "threshold_neg"):
        need(p[k] is None or p[k] > 0, f"{k} must be > 0 or null")
    for k in ("threshold_sigma", "refractory_us", "shot_noise_hz", "leak_rate_hz", "leak_rate_cov_decades",
              "shot_noise_inten_factor", "hot_pixel_rate_hz"):
        need(p[k] >= 0, f"{k} must be ≥ 0, got {p[k]}")
    need(0 < p["light_level"] <= 1, f"light_level must lie in (0, 1], got {p['light_level']}")
    need(0 <= p["hot_pixel_fraction"] <= 1, f"hot_pixel_fraction must lie in [0, 1], got {p['hot_pixel_fraction']}")
