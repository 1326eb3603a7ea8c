"""Generate a built-in synthetic scene: render the sub-frame stream, blur it, simulate events, keep the truth.

>>> g = generate("toy", {"seed": 3})          # a Generated: .scene (eigs.scene.Scene), .params, .stats ...
>>> write_generated(g, "scene.h5", contact_sheet="contact_sheet.png")

The intensity domain is stated once (docs/synthetic.md): textures are linearised on load, the scene is rendered
in linear intensity in [0, 1], the blurry frame is the mean of the exposure's sharp sub-frames in linear
intensity (all of them, or E²NeRF's 17 with ``blur_synthesis: e2nerf``: :mod:`eigs.synth.blur`; with
``frame_noise: davis346``, a DAVIS346's APS noise added to it: :mod:`eigs.synth.frame_noise`), frames
are stored 8-bit (``camera_response`` linear by default, sRGB optional), and events come from ln(Y + 1e-3) with Y the
BT.601 luma of the linear sub-frames.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from eigs.scene import (
    SHARP_KIND_BLUR_VIEW,
    SHARP_KIND_NOVEL_VIEW,
    Camera,
    Events,
    Frames,
    Poses,
    Scene,
    SharpImages,
    Trajectory,
)
from eigs.synth.blur import exposure_mean
from eigs.synth.raycast import RayCaster
from eigs.synth.response import encode
from eigs.synth.scenes import SceneSpec, get_spec, resolve_params
from eigs.synth.simulator import EventChunk, EventSimulator, SensorParams, log_luma
from eigs.synth.trajectory import CameraPath, Orbit, Shake, Timeline, spiral_orbit, still_view_indices
from eigs.util.progress import progress

log = logging.getLogger(__name__)

BLUR_TIME_SAMPLES = 17  # times per exposure at which scene points are projected to measure blur extent


@dataclass
class Generated:
    """A generated scene with what produced it. ``scene``: the :class:`eigs.scene.Scene` to write;
    ``path``: the ground-truth :class:`CameraPath` (callable: poses at any µs time); ``novel_c2w``: (N, 4, 4);
    ``blur_px``: (P,) float32 blur extents (px) of every visible scene point over all training views;
    ``stats``: counts and timings. ``scene.events`` is None when the events went to an ``event_sink``; their
    view index is ``view_index`` (V, 2) int64 either way."""

    scene: Scene
    params: dict[str, Any]
    spec: SceneSpec
    path: CameraPath
    caster: RayCaster
    novel_c2w: np.ndarray
    blur_px: np.ndarray
    view_index: np.ndarray
    stats: dict[str, Any] = field(default_factory=dict)


def intrinsics(width: int, height: int, fov_deg: float) -> np.ndarray:
    """(3, 3) pinhole K: fx = fy = (W/2)/tan(fov/2), principal point at the image centre (W/2, H/2) with pixel
    centres at j + 0.5."""
    f = 0.5 * width / np.tan(np.deg2rad(fov_deg) / 2)
    return np.array([[f, 0.0, width / 2.0], [0.0, f, height / 2.0], [0.0, 0.0, 1.0]])


def blur_extent(
    depth: np.ndarray, K: np.ndarray, c2w0: np.ndarray, c2w_t: np.ndarray
) -> np.ndarray:
    """Blur extent (px) of the scene points seen at pixel centres.

    ``depth``: (H, W) z-depth at the reference pose ``c2w0`` (4, 4) (+inf: background, skipped);
    ``c2w_t``: (T, 4, 4) poses along the exposure. Each visible point is back-projected, projected at every pose,
    and its extent is the largest distance between two of its T projections (the diameter of its image path).
    Returns (P,) float32.
    """
    h, w = depth.shape
    ok = np.isfinite(depth) & (depth > 0)
    ii, jj = np.nonzero(ok)
    if ii.size == 0:
        return np.zeros(0, np.float32)
    z = depth[ii, jj].astype(np.float64)
    kinv = np.linalg.inv(K)
    pc = np.stack([jj + 0.5, ii + 0.5, np.ones_like(z)], axis=1) @ kinv.T * z[:, None]
    pw = pc @ c2w0[:3, :3].T + c2w0[:3, 3]
    w2c = np.linalg.inv(c2w_t)
    cam = np.einsum("tij,pj->tpi", w2c[:, :3, :3], pw) + w2c[:, None, :3, 3]
    zc = np.maximum(cam[..., 2], 1e-6)
    uv = np.stack([K[0, 0] * cam[..., 0] / zc + K[0, 2], K[1, 1] * cam[..., 1] / zc + K[1, 2]], axis=-1)
    diam = np.zeros(ii.size)
    for a in range(uv.shape[0]):
        d = np.linalg.norm(uv[a + 1 :] - uv[a][None], axis=-1)
        if d.size:
            diam = np.maximum(diam, d.max(axis=0))
    return diam.astype(np.float32)


def _hist_quantile(hist: np.ndarray, q: float) -> int:
    """Quantile ``q`` of the values 1..64 counted in ``hist`` (index = value); 0 when empty."""
    c = np.cumsum(hist[1:])
    if c.size == 0 or c[-1] == 0:
        return 0
    return int(np.searchsorted(c, q * c[-1]) + 1)


def _sensor(p: dict[str, Any]) -> SensorParams:
    return SensorParams(
        contrast_threshold=p["contrast_threshold"],
        threshold_pos=p["threshold_pos"],
        threshold_neg=p["threshold_neg"],
        threshold_sigma=p["threshold_sigma"],
        refractory_us=p["refractory_us"],
        shot_noise_hz=p["shot_noise_hz"],
        leak_rate_hz=p["leak_rate_hz"],
        shot_noise_inten_factor=p["shot_noise_inten_factor"],
        leak_rate_cov_decades=p["leak_rate_cov_decades"],
        leak_random_phase=p["leak_random_phase"],
        hot_pixel_fraction=p["hot_pixel_fraction"],
        hot_pixel_rate_hz=p["hot_pixel_rate_hz"],
    )


def _frame_noise(
    p: dict[str, Any], root: np.random.Generator, height: int, width: int, channels: int
) -> Callable[[np.ndarray], np.ndarray] | None:
    """The APS noise of ``p["frame_noise"]`` (:mod:`eigs.synth.frame_noise`) as a function of one exposure's clean
    mean linear frame ``(H, W, C)``, or None (``none``). Its generator is the scene seed's third child, spawned only
    here, so noise-free scenes draw exactly what they drew before; the sensor's fixed pattern is drawn once, first."""
    from eigs.synth.frame_noise import MODELS, draw_fixed_pattern, expose

    if p["frame_noise"] == "none":
        return None
    model = MODELS[p["frame_noise"]]
    rng = np.random.default_rng(root.bit_generator.seed_seq.spawn(1)[0])
    pattern = draw_fixed_pattern(model, height, width, channels, rng)
    return lambda x: expose(x, model, pattern, rng)


def build_path(p: dict[str, Any], spec: SceneSpec, rng: np.random.Generator) -> tuple[CameraPath, Orbit]:
    """Ground-truth path of the training views and the novel-view orbit (in-between azimuths, other elevations).
    The views of :func:`still_view_indices` (``still_views``) are held still during their exposures."""
    kw = {"radius": p["orbit_radius"], "el_min": p["elevation_min"], "el_max": p["elevation_max"],
          "target": spec.target}
    train = spiral_orbit(p["n_train"], **kw)
    novel = spiral_orbit(max(p["n_novel"], 1), **{**kw, "el_min": p["elevation_max"], "el_max": p["elevation_min"]},
                         phase=0.5, az0=0.0)
    strength = p["shake"]
    if strength > 0 and (p["shake_rot_deg"] > 0 or p["shake_trans"] > 0):
        shake = Shake.random(rng, rot_deg=strength * p["shake_rot_deg"], trans=strength * p["shake_trans"],
                             fmin_hz=p["shake_fmin_hz"], fmax_hz=p["shake_fmax_hz"])
    else:
        shake = Shake.none()
    tl = Timeline(p["n_train"], p["exposure_us"], p["period_us"], p["lead_us"], p["subframes"], p["gap_subframes"],
                  p["lead_subframes"])
    still_idx = still_view_indices(p["n_train"], p["still_views"])
    still = None
    if still_idx.size:
        still = np.zeros(p["n_train"], bool)
        still[still_idx] = True
    return CameraPath(train, tl, shake, still), novel


def scene_camera(
    name: str,
    overrides: dict[str, Any] | None = None,
    *,
    layers: list[tuple[str, dict[str, Any] | None]] | None = None,
) -> Camera:
    """The camera :func:`generate` gives built-in scene ``name`` with these parameters (arguments as there)."""
    p = resolve_params(name, *(layers or []), ("overrides", overrides))
    return Camera(K=intrinsics(p["width"], p["height"], p["fov_deg"]), width=p["width"], height=p["height"])


def generate(
    name: str,
    overrides: dict[str, Any] | None = None,
    *,
    layers: list[tuple[str, dict[str, Any] | None]] | None = None,
    show_progress: bool = True,
    threads: int = 1,
    event_sink: Callable[[EventChunk], None] | None = None,
) -> Generated:
    """Generate built-in scene ``name`` (see ``eigs synth --list``).

    ``overrides``: parameter → value (see :data:`eigs.synth.scenes.DEFAULTS`); ``layers``: several named override
    mappings applied in order before ``overrides`` (the CLI passes its config file then ``--overrides``).
    Deterministic for given parameters (the ``seed`` drives shake, threshold mismatch and noise), whatever
    ``threads`` (frames rendered in parallel). ``event_sink``: called with each time-ordered chunk of events as
    it is simulated, which then are not kept (``scene.events`` is None; ``view_index`` and ``stats["events"]``
    describe them): memory bounded by one view's frames, not the recording's events (an 800×800 view and its gap
    make ~60 million events, 0.8 GB).
    """
    t_start = time.perf_counter()
    spec = get_spec(name)
    p = resolve_params(name, *(layers or []), ("overrides", overrides))
    width, height = p["width"], p["height"]
    K = intrinsics(width, height, p["fov_deg"])
    caster = RayCaster(spec.build(), background=spec.background, lighting=spec.lighting,
                       texture_size=p["texture_size"])
    root = np.random.default_rng(p["seed"])
    rng_shake, rng_sensor = (np.random.default_rng(s) for s in root.bit_generator.seed_seq.spawn(2))
    aps = _frame_noise(p, root, height, width, 3)
    path, novel_orbit = build_path(p, spec, rng_shake)
    tl = path.timeline
    n_views, n_bins = p["n_train"], p["n_bins"]
    sensor = _sensor(p)
    sim = EventSimulator(height, width, sensor, rng_sensor)
    ss = p["supersample"]

    light = float(p["light_level"])

    def dim(rgb: np.ndarray) -> np.ndarray:
        """Low light: the linear render × ``light_level`` (untouched at 1, so default scenes stay bit-identical)."""
        return rgb if light == 1.0 else (rgb * np.float32(light)).astype(rgb.dtype, copy=False)

    def render(times: np.ndarray, want_depth: bool = False):
        res = caster.render(path(times), K, width, height, supersample=ss, want_depth=want_depth, threads=threads)
        res.rgb = dim(res.rgb)
        return res

    blurry = np.zeros((n_views, height, width, 3), np.uint8)
    sharp0 = np.zeros((n_views, height, width, 3), np.uint8)
    chunks: list[EventChunk] = []
    bounds = tl.exposures.reshape(-1).astype(np.int64)  # (2V,) exposure starts and ends, µs
    before = np.zeros(bounds.shape[0], np.int64)  # events with t < each bound, over the chunks so far
    n_events = 0
    blur_parts: list[np.ndarray] = []
    frame_times: list[np.ndarray] = []
    t_render = t_sim = 0.0
    exp_hist = np.zeros_like(sim.crossing_hist)

    def feed(frames_rgb: np.ndarray, times: np.ndarray, *, reset_first: bool = False) -> None:
        nonlocal t_sim, n_events
        t0 = time.perf_counter()
        logs = log_luma(frames_rgb)
        for i in range(times.shape[0]):
            if sim.t is None:
                sim.reset(logs[i], float(times[i]))
                continue
            chunk = sim.step(logs[i], float(times[i]))
            np.add(before, np.searchsorted(chunk.t, bounds, side="left"), out=before)
            n_events += chunk.t.shape[0]
            if event_sink is None:
                chunks.append(chunk)
            else:
                event_sink(chunk)
            if reset_first and i == 0:
                sim.reset(logs[i], float(times[i]))
        t_sim += time.perf_counter() - t0

    lead_t = tl.lead_frame_times()
    if lead_t.size:
        t0 = time.perf_counter()
        frames = render(lead_t).rgb
        t_render += time.perf_counter() - t0
        feed(frames, lead_t)
        frame_times.append(lead_t)
    blur_idx = np.linspace(0, p["subframes"], BLUR_TIME_SAMPLES).round().astype(int)
    views = progress(range(n_views), desc=f"synth {name}", unit="view") if show_progress else range(n_views)
    for v in views:
        et = tl.exposure_frame_times(v)
        t0 = time.perf_counter()
        res = render(et)
        depth = caster.render(path(et[:1]), K, width, height, supersample=1, want_depth=True).depth
        t_render += time.perf_counter() - t0
        frames = res.rgb
        mean = exposure_mean(frames, p["blur_synthesis"])  # linear (H, W, 3) float64 (eigs.synth.blur)
        blurry[v] = encode(mean if aps is None else aps(mean), p["camera_response"])
        sharp0[v] = encode(frames[0], p["camera_response"])
        blur_parts.append(blur_extent(depth[0], K, path(et[:1])[0], path(et[np.unique(blur_idx)])))
        hist0 = sim.crossing_hist.copy()
        feed(frames, et, reset_first=p["reset_at_exposure"])
        exp_hist += sim.crossing_hist - hist0
        frame_times.append(et)
        gt = tl.gap_frame_times(v)
        if gt.size:
            t0 = time.perf_counter()
            gframes = render(gt).rgb
            t_render += time.perf_counter() - t0
            feed(gframes, gt)
            frame_times.append(gt)

    exposures = tl.exposures
    # chunks are time-ordered, so the events before a bound are the sum of each chunk's
    view_index = before.reshape(n_views, 2)
    events = None
    if event_sink is None:
        ev = EventChunk.concat(chunks)
        events = Events(ev.x, ev.y, ev.t, ev.p, view_index)

    latent_t = tl.latent_times(n_bins)
    latent_c2w = path(latent_t.ravel()).reshape(n_views, n_bins + 1, 4, 4)
    traj_t = np.concatenate(frame_times)
    trajectory = Trajectory(traj_t.astype(np.int64), path(traj_t))

    n_novel = p["n_novel"]
    novel_c2w = novel_orbit.poses()[:n_novel]
    t0 = time.perf_counter()
    novel_rgb = (dim(caster.render(novel_c2w, K, width, height, supersample=ss, threads=threads).rgb) if n_novel
                 else np.zeros((0, height, width, 3), np.float32))
    t_render += time.perf_counter() - t0
    sharp = SharpImages(
        images=np.concatenate([sharp0, encode(novel_rgb, p["camera_response"])]),
        c2w=np.concatenate([latent_c2w[:, 0], novel_c2w]),
        t_us=np.concatenate([latent_t[:, 0], np.full(n_novel, -1, np.int64)]).astype(np.int64),
        kind=np.concatenate([np.full(n_views, SHARP_KIND_BLUR_VIEW), np.full(n_novel, SHARP_KIND_NOVEL_VIEW)]
                            ).astype(np.uint8),
        view=np.concatenate([np.arange(n_views), np.full(n_novel, -1)]).astype(np.int64),
    )
    background = encode(np.asarray(spec.background) * light, p["camera_response"]).astype(np.float64) / 255.0
    scene = Scene(
        name=name,
        camera=Camera(K=K, width=width, height=height),
        channels=3,
        camera_response=p["camera_response"],
        synthetic=True,
        background=background,
        contrast_threshold=float(p["contrast_threshold"]),
        source=f"eigs synth --scene {name} (seed {p['seed']}"
        + (f", preset {p['preset']}" if p["preset"] else "")
        + (f", frame noise {p['frame_noise']}" if aps is not None else "")
        + (f", blur {p['blur_synthesis']}" if p["blur_synthesis"] != "average" else "")
        + ")",
        frames=Frames(blurry=blurry, exposure_us=exposures.astype(np.int64)),
        events=events,
        poses=Poses(latent_c2w=latent_c2w, latent_t_us=latent_t.astype(np.int64), source="ground-truth"),
        trajectory=trajectory,
        sharp=sharp,
    )
    blur_px = np.concatenate(blur_parts) if blur_parts else np.zeros(0, np.float32)
    n_in = int((view_index[:, 1] - view_index[:, 0]).sum())
    stats = {
        "seconds": time.perf_counter() - t_start,
        "render_seconds": t_render,
        "simulate_seconds": t_sim,
        "frames_rendered": int(traj_t.size + n_novel),
        "events": n_events,
        "events_in_exposures": n_in,
        "max_crossings_per_step": sim.max_crossings_per_step,
        "exposure_crossings_p99": _hist_quantile(exp_hist, 0.99),
        "exposure_crossings_p999": _hist_quantile(exp_hist, 0.999),
        "exposure_crossings_max": int(np.flatnonzero(exp_hist)[-1]) if exp_hist.any() else 0,
        "still_views": [int(v) for v in np.flatnonzero(path.still)] if path.still is not None else [],
        "blur_median_px": float(np.median(blur_px)) if blur_px.size else 0.0,
        "blur_p90_px": float(np.percentile(blur_px, 90)) if blur_px.size else 0.0,
    }
    log.info(
        "%s: %d views %dx%d, %d events (%d inside exposures), blur median %.1f px / p90 %.1f px, "
        "crossings per active pixel-step in exposures p99 %d / p99.9 %d / max %d, "
        "%.1f s (render %.1f s, events %.1f s)",
        name, n_views, width, height, stats["events"], n_in, stats["blur_median_px"], stats["blur_p90_px"],
        stats["exposure_crossings_p99"], stats["exposure_crossings_p999"], stats["exposure_crossings_max"],
        stats["seconds"], t_render, t_sim,
    )
    if stats["still_views"]:
        log.info("%s: views held still during their exposure (sharp frames): %s", name, stats["still_views"])
    return Generated(scene, p, spec, path, caster, novel_c2w, blur_px, view_index, stats)


def write_generated(g: Generated, path, *, contact_sheet=None) -> None:
    """Write the scene file (atomic, validated) and optionally its contact sheet PNG."""
    from eigs.scene import write_scene

    write_scene(g.scene, path)
    if contact_sheet is not None:
        from eigs.synth.contact_sheet import write_contact_sheet

        write_contact_sheet(g.scene, contact_sheet)
