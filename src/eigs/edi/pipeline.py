"""The ``edi`` stage: a scene → :class:`~eigs.artifacts.edi.EdiResult` (+ latent PNGs).

Steps per scene (``docs/edi.md``): choose the mode, the latent times and the bins; build the hot-pixel mask;
per view count the events (views under :data:`SHARP_EVENTS_PER_PIXEL` are copied and marked sharp), bin them and,
in estimated mode, build the exact exposure integral; estimate the threshold (scene or per view); compute the
latent frames and store them in the scene's pixel domain. A scene without events (or run with ``events=False``)
passes every view through as sharp: no binning, no threshold search.

Memory: the raw events come as an :class:`eigs.scene.EventSource` and are read a view's window at a time (the
whole stream only in chunks, for the hot-pixel rates and the gap counts), and the per-event integrals are kept only
where a later phase needs them all at once (the threshold's evidence views; the per-pixel calibration's views,
within :data:`INTEGRAL_BUDGET_BYTES`); the others are rebuilt from their window when their latent frames are made.
An 800×800 recording of 30 views (~1.8 billion events, 23 GB) is deblurred in a bounded part of that.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np

from eigs.artifacts.edi import EdiResult
from eigs.edi import binning
from eigs.edi import calibration as cal
from eigs.edi import mask as mask_mod
from eigs.edi import threshold as thr
from eigs.edi.edi import (
    E2NERF_C,
    ExposureIntegral,
    blur_extent_px,
    edi_continuous,
    edi_discrete,
    edi_e2nerf,
    from_linear,
    to_linear,
)
from eigs.edi.options import DEFAULT_BINS, MODES, SCOPES, EdiOptions
from eigs.errors import EigsError
from eigs.scene.model import Events, EventSource, Scene
from eigs.util.progress import progress

log = logging.getLogger(__name__)

SHARP_EVENTS_PER_PIXEL = 0.01  # views below this many events per pixel over the exposure are copied
SEARCH_VIEWS = 12  # at most this many (evenly spaced) views enter the scene-scope threshold energy
FALLBACK_C = 0.2  # threshold when nothing can be estimated (no view has events)
# per-pixel calibration: the polarity integrals held at once (~24 bytes per segment, a segment per event and per
# pixel with events); over it, an evenly spaced subset of the gaps is fitted (no scene of the suite comes near it)
INTEGRAL_BUDGET_BYTES = 6 << 30


def is_e2nerf_scene(scene: Scene, raw: bool | None = None) -> bool:
    """Scenes ingested from E²NeRF layouts: the ``source`` attribute starts with E²NeRF's name (``eigs ingest`` writes
    ``e2nerf-synthetic:<folder>`` and ``e2nerf-real:<folder>``), or the events come pre-binned without raw timestamps
    (only E²NeRF's ``events.pt`` provides that). A source that only mentions E²NeRF later is not one: a built-in
    scene whose blur is made as E²NeRF made its blur (``eigs synth … (seed 0, blur e2nerf)``) has our simulator's
    events and thresholds, and E²NeRF's fixed c = 0.3 would deblur it with the wrong threshold. ``raw``: whether
    the scene has raw events (default: ``scene.events`` is there; a scene read without them says so here)."""
    if scene.source.lower().replace("²", "2").replace("-", "").replace("_", "").startswith("e2nerf"):
        return True
    return scene.binned is not None and not (scene.events is not None if raw is None else raw)


def resolve_mode(scene: Scene, mode: str, raw: bool | None = None) -> str:
    if mode not in MODES:
        raise EigsError(None, f"--mode must be one of {MODES}, got {mode!r}")
    if mode == "auto":
        return "e2nerf" if is_e2nerf_scene(scene, raw) else "estimated"
    return mode


def events_before(source: EventSource, times: np.ndarray) -> np.ndarray:
    """(K,) int64 number of events with t < times[k] (the stream is time-sorted: the sum of each chunk's)."""
    times = np.asarray(times, np.int64)
    out = np.zeros(times.shape, np.int64)
    for c in source.chunks():
        out += np.searchsorted(c.t, times, side="left")
    return out


def _view_slices(path: str, scene: Scene, source: EventSource) -> np.ndarray:
    """(V, 2) int64 [start, stop) offsets of each view's exposure events in ``source``."""
    assert scene.frames is not None and scene.frames.exposure_us is not None
    if source.view_index is not None:
        return np.asarray(source.view_index, np.int64)
    exp = scene.frames.exposure_us
    return events_before(source, exp.reshape(-1)).reshape(-1, 2)


def choose_latent_times(path: str, scene: Scene, bins: int) -> np.ndarray:
    """(V, B + 1) int64 latent times: the scene's ``poses/latent_t_us`` when it has B + 1 per view inside the
    exposures, else :func:`eigs.edi.binning.latent_times`."""
    assert scene.frames is not None and scene.frames.exposure_us is not None
    exp = scene.frames.exposure_us
    formula = binning.latent_times(exp, bins)
    if scene.poses is not None and scene.poses.latent_t_us.shape == formula.shape:
        lt = scene.poses.latent_t_us
        inside = np.all((lt >= exp[:, :1]) & (lt <= exp[:, 1:]))
        if inside and np.all(np.diff(lt, axis=1) > 0):
            dev = int(np.abs(lt - formula).max()) if lt.size else 0
            log.info("latent times from the scene's poses (max deviation from the midpoint formula: %d µs)", dev)
            return lt.astype(np.int64)
        log.warning("the scene's latent_t_us are not strictly inside the exposures; using the midpoint formula")
    return formula


def _estimate_threshold(evidence: list[thr.ViewEvidence]) -> float:
    c, _ = thr.bounded_search(lambda c: sum(e.energy(c) for e in evidence))
    return c


def without_events(scene: Scene) -> Scene:
    """``scene`` without its raw and pre-binned events (a shallow copy; the arrays are shared)."""
    return replace(scene, events=None, binned=None)


@dataclass
class _ViewEvents:
    """Per-view event data of one scene (V views, B bins, H × W pixels)."""

    cum: np.ndarray  # (V, B + 1, H, W) int32 signed event counts from the first latent time to each latent time
    event_count: np.ndarray  # (V,) int64 events in each view's exposure
    slices: np.ndarray | None  # (V, 2) int64 [start, stop) of each view's events in the source (raw events)
    integrals: list[ExposureIntegral | None]  # exact exposure integrals kept (the threshold's evidence views)
    evals: list[tuple[np.ndarray, np.ndarray] | None]  # (eval_counts, rate) for the threshold energy
    source: EventSource | None = None  # the raw events (None: pre-binned or none)
    exact: np.ndarray | None = None  # (V,) bool: the view has an exact exposure integral (estimated, with events)
    times: np.ndarray | None = None  # (V, B + 1) int64 latent times
    exposure: np.ndarray | None = None  # (V, 2) int64
    hot: np.ndarray | None = None  # (H, W) bool

    def window(self, v: int) -> Events:
        """View ``v``'s exposure events, read from the source."""
        assert self.source is not None and self.slices is not None
        return self.source.window(int(self.slices[v, 0]), int(self.slices[v, 1]))

    def integral(self, v: int) -> ExposureIntegral | None:
        """View ``v``'s exact exposure integral: the kept one, else built from its window; None without one."""
        if self.integrals[v] is not None or self.exact is None or not self.exact[v]:
            return self.integrals[v]
        assert self.times is not None and self.exposure is not None and self.hot is not None
        e = self.window(v)
        s, t_end = (int(u) for u in self.exposure[v])
        h, w = self.hot.shape
        return ExposureIntegral(e.x, e.y, e.t, e.p, s, t_end, int(self.times[v, 0]), h, w, self.hot)


def compute_edi(
    scene: Scene, opts: EdiOptions, path: str = "", *, events: bool = True, source: EventSource | None = None
) -> EdiResult:
    """Run EDI on every view of ``scene``. ``path`` names the scene file in error messages. ``events=False``
    (``eigs edi --no-events``, the workflow's ``edi_frames`` job for a scene configured with ``events: false``)
    ignores the scene's raw and pre-binned events: the result is the one of the same scene without events, every
    view passed through as sharp (:func:`without_events`). ``source``: the raw events when ``scene`` was read
    without them (``eigs edi`` passes the file's :class:`eigs.scene.EventFile`); default ``scene.events``.

    Phases: check the options → bins and latent times → hot-pixel mask → per-view events → sharp views →
    threshold → per-pixel thresholds → latent frames.
    """
    path = path or scene.name
    scene.require("frames", path=path)
    assert scene.frames is not None
    if source is None:
        source = scene.events
    if not events:
        scene, source = without_events(scene), None
    raw = source is not None and len(source) > 0
    mode = _check_options(scene, opts, source is not None)
    prebinned = scene.binned is not None and not raw
    bins, times = _bins_and_times(path, scene, opts, raw, prebinned)
    if not raw and not prebinned:
        if events:
            log.warning("the scene has no events: every view is passed through as sharp")
        else:
            log.info("events not used (--no-events): every view is passed through as sharp")
    hot = _hot_pixel_mask(scene, source, opts, mode, raw, prebinned)
    # instantaneous frames (no exposure windows) have no events inside them: zero counts, passed through
    in_exposures = raw and scene.frames.exposure_us is not None
    ve = _view_events(path, scene, source if in_exposures else None, opts, mode, bins, times, hot, prebinned)
    h, w = scene.frames.blurry.shape[1:3]
    sharp, active = _sharp_views(ve.event_count, h, w)
    lin = _linear_frames(scene, mode, active)
    thresholds, scope = _thresholds(scene, opts, mode, ve, lin, active)
    maps = None
    if mode == "estimated" and opts.per_pixel_threshold:
        # the evidence's exposure integrals have served; with per-pixel maps the latent frames do not read them
        ve.integrals[:] = [None] * len(ve.integrals)
        maps = _per_pixel_thresholds(scene, opts, thresholds, ve, active)
    latent, extent = _latent_frames(scene, opts, mode, times, ve, lin, thresholds, sharp, maps, hot)
    c_pos_map, c_neg_map, _ = maps if maps is not None else (None, None, {})
    return EdiResult(
        latent=latent,
        timestamps_us=times.astype(np.int64),
        cum_counts=ve.cum,
        threshold=thresholds.astype(np.float64),
        sharp=sharp,
        event_count=ve.event_count,
        events_per_pixel=ve.event_count.astype(np.float64) / float(h * w),
        blur_extent_px=extent,
        mode=mode,
        threshold_scope=scope,
        scene_name=scene.name,
        event_mask=hot,
        threshold_pos_map=c_pos_map,
        threshold_neg_map=c_neg_map,
    )


def _check_options(scene: Scene, opts: EdiOptions, raw: bool) -> str:
    """The resolved mode; raises :class:`EigsError` for an unknown scope or an implausible threshold."""
    mode = resolve_mode(scene, opts.mode, raw)
    if opts.threshold_scope not in SCOPES:
        raise EigsError(None, f"--threshold-scope must be one of {SCOPES}, got {opts.threshold_scope!r}")
    if opts.threshold is not None and not (thr.C_MIN / 100 <= opts.threshold <= 10):
        raise EigsError(None, f"--threshold must be a positive contrast threshold (log units), got {opts.threshold}")
    return mode


def _bins_and_times(
    path: str, scene: Scene, opts: EdiOptions, raw: bool, prebinned: bool
) -> tuple[int, np.ndarray]:
    """B and the (V, B + 1) int64 latent times (µs): the scene's bin edges when pre-binned, else
    :func:`choose_latent_times`; for instantaneous frames (``frames.t_us``, no exposure windows) every latent
    time is the frame's timestamp; with neither, zeros (or the scene's latent times)."""
    assert scene.frames is not None
    if prebinned:
        assert scene.binned is not None
        bins = binning.check_prebinned(path, scene.binned.n_bins, opts.bins)
        return bins, scene.binned.bin_edges_us.astype(np.int64)
    bins = binning.check_bins(opts.bins if opts.bins is not None else DEFAULT_BINS)
    if scene.frames.exposure_us is None and scene.frames.t_us is not None:
        log.info("frames are instants (timestamps, no exposure windows): every view is passed through as sharp")
        return bins, np.repeat(scene.frames.t_us.astype(np.int64)[:, None], bins + 1, axis=1)
    if raw and (scene.frames.exposure_us is None):
        raise EigsError(
            path,
            "the scene has raw events but no exposure times, so its events cannot be assigned to frames; "
            "re-ingest with --exposure-us START,END (or an exposure file)",
        )
    if scene.frames.exposure_us is not None:
        return bins, choose_latent_times(path, scene, bins)
    times = np.zeros((scene.frames.blurry.shape[0], bins + 1), np.int64)
    if scene.poses is not None and scene.poses.latent_t_us.shape == times.shape:
        times = scene.poses.latent_t_us.astype(np.int64)
    return bins, times


def _hot_pixel_mask(
    scene: Scene, source: EventSource | None, opts: EdiOptions, mode: str, raw: bool, prebinned: bool
) -> np.ndarray:
    """(H, W) bool hot-pixel / flicker mask (estimated mode only: the E²NeRF mode reproduces E²NeRF exactly)."""
    assert scene.frames is not None
    h, w = scene.frames.blurry.shape[1:3]
    if mode != "estimated" or opts.mask_top <= 0:
        return np.zeros((h, w), dtype=bool)
    if raw:
        assert source is not None
        rate = np.zeros((h, w), np.int64)
        for c in source.chunks():
            rate += mask_mod.event_rate_map(c.x, c.y, h, w)
    elif prebinned:
        assert scene.binned is not None
        rate = np.abs(scene.binned.counts).sum(axis=(0, 1))
    else:
        rate = np.zeros((h, w), np.int64)
    hot = mask_mod.hot_pixel_mask(rate, opts.mask_top, opts.mask_factor)
    log.info("hot-pixel/flicker mask: %d pixels (%.3f %%)", int(hot.sum()), 100.0 * hot.mean())
    return hot


def _evidence_views(opts: EdiOptions, active: np.ndarray) -> np.ndarray:
    """The views whose evidence the threshold estimate reads: none with a given threshold, at most
    :data:`SEARCH_VIEWS` evenly spaced ones per scene, every active one per view."""
    if opts.threshold is not None or active.size == 0:
        return np.zeros(0, np.int64)
    if opts.threshold_scope != "scene":
        return active
    idx = np.unique(np.linspace(0, active.size - 1, min(SEARCH_VIEWS, active.size)).round().astype(int))
    return active[idx]


def _view_events(
    path: str,
    scene: Scene,
    source: EventSource | None,
    opts: EdiOptions,
    mode: str,
    bins: int,
    times: np.ndarray,
    hot: np.ndarray,
    prebinned: bool,
) -> _ViewEvents:
    """Per view: count the events, bin them at the latent times and, in estimated mode, for the threshold's evidence
    views (:func:`_evidence_views`), build the exact exposure integral and the threshold-energy maps (views under
    :data:`SHARP_EVENTS_PER_PIXEL` get neither; the others' integrals are built again when their latent frames are
    made, :meth:`_ViewEvents.integral`). ``source``: the raw events of a scene with exposures, else None."""
    assert scene.frames is not None
    v_n, h, w = scene.frames.blurry.shape[:3]
    cum = np.zeros((v_n, bins + 1, h, w), np.int32)
    event_count = np.zeros(v_n, np.int64)
    slices = _view_slices(path, scene, source) if source is not None else None
    integrals: list[ExposureIntegral | None] = [None] * v_n
    evals: list[tuple[np.ndarray, np.ndarray] | None] = [None] * v_n
    exact = None
    keep: set[int] = set()
    if slices is not None:
        event_count[:] = slices[:, 1] - slices[:, 0]
        if mode == "estimated":
            exact = event_count >= SHARP_EVENTS_PER_PIXEL * h * w
            keep = {int(v) for v in _evidence_views(opts, np.flatnonzero(exact))}
    ve = _ViewEvents(cum, event_count, slices, integrals, evals, source, exact, times,
                     scene.frames.exposure_us, hot)
    views = range(v_n)
    for v in progress(views, desc="edi: bin events", total=v_n, unit="view") if opts.show_progress else views:
        if slices is not None:
            assert scene.frames.exposure_us is not None
            e = ve.window(v)
            x, y, t, p = e.x, e.y, e.t, e.p
            cum[v] = binning.cumulative_counts(binning.bin_events(x, y, t, p, times[v], h, w, hot))
            if v in keep:
                s, end = (int(u) for u in scene.frames.exposure_us[v])
                integrals[v] = ExposureIntegral(x, y, t, p, s, end, int(times[v, 0]), h, w, hot)
                evals[v] = _eval_maps(x, y, t, p, s, end, int(times[v, 0]), bins + 1, h, w, hot)
        elif prebinned:
            assert scene.binned is not None
            counts = np.where(hot[None], 0, scene.binned.counts[v])
            event_count[v] = int(np.abs(scene.binned.counts[v]).astype(np.int64).sum())
            cum[v] = binning.cumulative_counts(counts)
            evals[v] = _eval_maps_binned(counts)
    return ve


def _sharp_views(event_count: np.ndarray, h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    """((V,) bool views passed through as sharp (under :data:`SHARP_EVENTS_PER_PIXEL`), indices of the others)."""
    sharp = event_count.astype(np.float64) / float(h * w) < SHARP_EVENTS_PER_PIXEL
    active = np.flatnonzero(~sharp)
    log.info("%d of %d views have events; %d are passed through as sharp", active.size, sharp.size, int(sharp.sum()))
    return sharp, active


def _linear_frames(scene: Scene, mode: str, active: np.ndarray) -> list[np.ndarray | None]:
    """Per view: the blurry frame as (H, W, C) float64 linear intensity (estimated mode, views with events)."""
    assert scene.frames is not None
    lin: list[np.ndarray | None] = [None] * scene.frames.blurry.shape[0]
    if mode != "e2nerf":
        for v in active:
            lin[v] = to_linear(scene.frames.blurry[v], scene.camera_response)
    return lin


def _thresholds(
    scene: Scene,
    opts: EdiOptions,
    mode: str,
    ve: _ViewEvents,
    lin: list[np.ndarray | None],
    active: np.ndarray,
) -> tuple[np.ndarray, str]:
    """((V,) contrast thresholds, scope): given, E²NeRF's, or estimated per scene (at most :data:`SEARCH_VIEWS`
    evenly spaced views) or per view."""
    v_n = ve.event_count.shape[0]
    thresholds = np.full(v_n, np.nan)
    if mode == "e2nerf":
        thresholds[:] = E2NERF_C if opts.threshold is None else opts.threshold
        return thresholds, "given"
    evidence = {
        int(v): thr.ViewEvidence(lin[v], ve.integrals[v], ve.cum[v], *ve.evals[v])
        for v in active
        if ve.evals[v] is not None
    }
    if opts.threshold is not None:
        thresholds[:] = opts.threshold
        return thresholds, "given"
    if not evidence:
        thresholds[:] = scene.contrast_threshold or FALLBACK_C
        # a warning when events were there but too few; none used at all was said already
        (log.warning if ve.event_count.any() else log.info)(
            "no view has events: threshold set to %.3f without estimation", thresholds[0]
        )
        return thresholds, opts.threshold_scope
    if opts.threshold_scope == "scene":
        keys = sorted(evidence)
        idx = np.unique(np.linspace(0, len(keys) - 1, min(SEARCH_VIEWS, len(keys))).round().astype(int))
        pick = [keys[i] for i in idx]
        c = _estimate_threshold([evidence[k] for k in pick])
        log.info("estimated contrast threshold (scene, %d views): c = %.4f", len(pick), c)
        thresholds[:] = c
        return thresholds, "scene"
    it = progress(sorted(evidence), desc="edi: threshold", unit="view") if opts.show_progress else evidence
    for v in it:
        thresholds[v] = _estimate_threshold([evidence[v]])
    fill = float(np.median(thresholds[sorted(evidence)]))
    thresholds[np.isnan(thresholds)] = fill
    log.info("estimated thresholds per view: median %.4f, range %.4f–%.4f", fill, *np.nanpercentile(
        thresholds, [0, 100]))
    return thresholds, "view"


def _latent_frames(
    scene: Scene,
    opts: EdiOptions,
    mode: str,
    times: np.ndarray,
    ve: _ViewEvents,
    lin: list[np.ndarray | None],
    thresholds: np.ndarray,
    sharp: np.ndarray,
    maps: tuple[np.ndarray, np.ndarray, dict[int, cal.PolarityIntegral]] | None,
    hot: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """((V, B + 1, H, W, C) float32 latent frames in the scene's pixel domain [0, 1], (V,) blur extent in px).
    Sharp views are copied; E²NeRF mode runs its exact model; estimated mode uses the per-pixel maps when there
    are any, else the exact exposure integral, else the discrete model."""
    assert scene.frames is not None
    blurry = scene.frames.blurry
    v_n, h, w, ch = blurry.shape
    c_pos_map, c_neg_map, pol_ints = maps if maps is not None else (None, None, {})
    latent = np.empty((v_n, ve.cum.shape[1], h, w, ch), np.float32)
    extent = np.zeros(v_n, np.float64)
    views = range(v_n)
    for v in progress(views, desc="edi: latent frames", total=v_n, unit="view") if opts.show_progress else views:
        if sharp[v]:
            latent[v] = (blurry[v].astype(np.float32) / 255.0)[None]
            continue
        c = float(thresholds[v])
        if mode == "e2nerf":
            lat = edi_e2nerf(blurry[v], ve.cum[v], c)
            latent[v] = (np.clip(lat, 0.0, 255.0) / 255.0).astype(np.float32)
        else:
            if c_pos_map is not None and c_neg_map is not None:
                lat = _latent_per_pixel(scene, v, times[v], lin[v], pol_ints.get(v), c_pos_map, c_neg_map, ve, hot)
            elif (integral := ve.integral(v)) is not None:
                lat = edi_continuous(lin[v], ve.cum[v], integral.log_mean_exp(c), c)
            else:
                lat = edi_discrete(lin[v], ve.cum[v], c)
            latent[v] = from_linear(np.clip(lat, 0.0, 1.0), scene.camera_response).astype(np.float32)
        extent[v] = blur_extent_px(latent[v])
    return latent, extent


def _calibration_gaps(gaps: np.ndarray, event_count: np.ndarray, hw: int) -> np.ndarray:
    """(V − 1,) bool: the usable ``gaps`` whose two views' polarity integrals fit :data:`INTEGRAL_BUDGET_BYTES`
    together: all of them when they fit, else the most evenly spaced ones that do."""
    n = event_count.astype(np.int64)
    per_view = 24 * (n + np.minimum(n, hw)) + 24 * np.minimum(n, hw)  # segments, then per-pixel arrays

    def cost(sel: np.ndarray) -> int:
        return int(per_view[np.unique(np.concatenate([sel, sel + 1]))].sum()) if sel.size else 0

    usable = np.flatnonzero(gaps)
    for k in range(usable.size, 0, -1):
        sel = usable[np.unique(np.linspace(0, usable.size - 1, k).round().astype(int))]
        if cost(sel) <= INTEGRAL_BUDGET_BYTES:
            out = np.zeros_like(gaps)
            out[sel] = True
            if k < usable.size:
                log.info("per-pixel calibration: %d of %d gaps (their integrals, %.1f GB, within the %.1f GB budget; "
                         "all would take %.1f GB)", sel.size, usable.size, cost(sel) / 1e9,
                         INTEGRAL_BUDGET_BYTES / 1e9, cost(usable) / 1e9)
            return out
    return np.zeros_like(gaps)


def _per_pixel_thresholds(
    scene: Scene,
    opts: EdiOptions,
    thresholds: np.ndarray,
    ve: _ViewEvents,
    active: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, dict[int, cal.PolarityIntegral]] | None:
    """Per-pixel (c⁺, c⁻) maps from the gap constraints (:mod:`eigs.edi.calibration`) and the per-view
    polarity integrals built for them (the latent frames build the others); None (global threshold, logged) when
    the data cannot support them."""
    import time

    def fallback(why: str) -> None:
        log.info("per-pixel threshold calibration not applied (%s): global threshold used", why)

    if opts.threshold is not None:
        fallback("threshold given")
        return None
    src, slices, frames, hot = ve.source, ve.slices, scene.frames, ve.hot
    if src is None or len(src) == 0 or slices is None or frames is None or frames.exposure_us is None:
        fallback("no raw events")
        return None
    assert hot is not None
    if active.size == 0:
        fallback("no view has events")
        return None
    t0 = time.perf_counter()
    exp = frames.exposure_us.astype(np.int64)
    if not np.all(np.diff(exp[:, 0]) > 0):
        fallback("exposure starts not increasing")
        return None
    # gap v has events when some event lies in [end_v, start_{v+1}): the slices count the events before each bound
    gaps = cal.usable_gaps_from_counts(slices[:-1, 1], slices[1:, 0], exp)
    if int(gaps.sum()) < cal.MIN_GAPS:
        fallback(f"{int(gaps.sum())} exposure gaps with events, at least {cal.MIN_GAPS} needed")
        return None
    v_n = exp.shape[0]
    h, w = frames.blurry.shape[1:3]
    gaps = _calibration_gaps(gaps, ve.event_count, h * w)
    if int(gaps.sum()) < cal.MIN_GAPS:
        fallback(f"the integrals of {cal.MIN_GAPS} gaps exceed the memory budget")
        return None
    c0 = float(np.median(thresholds[active]))
    need = np.flatnonzero(np.concatenate([gaps, [False]]) | np.concatenate([[False], gaps]))
    ints: list[cal.PolarityIntegral | None] = [None] * v_n
    for v in need:
        e = ve.window(int(v))
        ints[v] = cal.PolarityIntegral(e.x, e.y, e.t, e.p, exp[v, 0], exp[v, 1], h, w, hot)
    # events from start_v to start_{v+1} (the exposure and the gap); the starts must increase for the binning
    n_pos = np.zeros((v_n - 1, h, w), np.int64)
    n_neg = np.zeros((v_n - 1, h, w), np.int64)
    for c in src.chunks():
        on, off = binning.polarity_counts(c.x, c.y, c.t, c.p, exp[:, 0], h, w, hot)
        n_pos += on
        n_neg += off
    bsat = [cal.log_luma_and_sigma(frames.blurry[v], scene.camera_response) for v in range(v_n)]
    b, sigma_b, sat = (np.stack(z) for z in zip(*bsat, strict=True))
    res = cal.calibrate(b, sigma_b, sat, ints, n_pos, n_neg, gaps, c0, mask=hot)
    if not (np.all(np.isfinite(res.c_pos)) and np.all(np.isfinite(res.c_neg))):
        fallback("non-finite estimate")
        return None
    qp = np.percentile(res.c_pos, [25, 50, 75])
    qn = np.percentile(res.c_neg, [25, 50, 75])
    log.info(
        "per-pixel thresholds from %d gaps: c+ median %.4f (IQR %.4f–%.4f), c- median %.4f (IQR %.4f–%.4f); "
        "prior centre (%.4f, %.4f), global c = %.4f; median |gap residual| %.4f → %.4f; %.1f s",
        res.n_gaps, qp[1], qp[0], qp[2], qn[1], qn[0], qn[2], *res.pooled, c0,
        res.residual_before, res.residual_after, time.perf_counter() - t0,
    )
    return res.c_pos, res.c_neg, {int(v): ints[v] for v in active if ints[v] is not None}


def _latent_per_pixel(
    scene: Scene,
    v: int,
    times: np.ndarray,
    lin: np.ndarray,
    integral: cal.PolarityIntegral | None,
    c_pos: np.ndarray,
    c_neg: np.ndarray,
    ve: _ViewEvents,
    hot: np.ndarray,
) -> np.ndarray:
    """(L, H, W, C) linear latent frames of view ``v`` with the per-pixel maps (reference = exposure start);
    ``integral``: its polarity integral when the calibration kept it, else built here from its window."""
    assert scene.frames is not None and scene.frames.exposure_us is not None
    e = ve.window(v)
    start, end = (int(u) for u in scene.frames.exposure_us[v])
    h, w = lin.shape[:2]
    if integral is None:
        integral = cal.PolarityIntegral(e.x, e.y, e.t, e.p, start, end, h, w, hot)
    s_pos, s_neg = cal.counts_before(e.x, e.y, e.t, e.p, start, times, h, w, hot)
    return cal.edi_per_pixel(lin, s_pos, s_neg, integral.log_mean_exp(c_pos, c_neg), c_pos, c_neg)


def _eval_maps(
    x: np.ndarray,
    y: np.ndarray,
    t: np.ndarray,
    p: np.ndarray,
    start: int,
    end: int,
    t_ref: int,
    n: int,
    h: int,
    w: int,
    hot: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Energy evaluation times τ_j at the midpoints of ``n`` equal slices of the exposure (so every window lies
    inside it): returns ((n, H, W) event integral from ``t_ref`` to τ_j, (n, H, W) signed events in slice j)."""
    edges = start + (np.arange(n + 1, dtype=np.int64) * (end - start)) // n
    if np.any(np.diff(edges) <= 0):  # exposure shorter than n µs
        edges = np.arange(n + 1, dtype=np.int64) + start
    mids = (edges[:-1] + edges[1:]) // 2
    rate = binning.bin_events(x, y, t, p, edges, h, w, hot).astype(np.float64)
    cut = np.unique(np.concatenate([[t_ref], mids]))
    if cut.shape[0] > 1:
        cum = binning.cumulative_counts(binning.bin_events(x, y, t, p, cut, h, w, hot))
        pos = np.searchsorted(cut, mids)
        counts = cum[pos].astype(np.float64)
    else:
        counts = np.zeros((n, h, w))
    return counts, rate


def _eval_maps_binned(counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Binned analogue of :func:`_eval_maps`: the interior latent times k = 1..B−1 (all B + 1 when B = 1), with
    the sum of the two bins around each as its event map."""
    c = counts.astype(np.float64)
    cum = binning.cumulative_counts(counts).astype(np.float64)
    nb = c.shape[0]
    if nb == 1:
        return cum, np.concatenate([c, c])
    return cum[1:nb], c[:-1] + c[1:]
