"""``still_views``: training views held still during their exposure. Which views, the path (frozen exposure,
continuous catch-up, later views unchanged), the default leaves every scene unchanged, the frames (blurry =
sharp bit for bit), the events (none but sensor noise inside a still exposure) and EDI marks exactly those
views sharp."""

from __future__ import annotations

import numpy as np
import pytest

from eigs.edi.pipeline import EdiOptions, compute_edi
from eigs.errors import EigsError
from eigs.synth.generate import build_path, generate
from eigs.synth.scenes import get_spec, resolve_params
from eigs.synth.trajectory import still_view_indices

# toy at its own 64×48 and time base, with fewer sub-frames (fast); 8 views, still_views 0.25 → views 2 and 6
FAST = {"subframes": 16, "gap_subframes": 10, "n_novel": 1}
STILL = [2, 6]


@pytest.mark.parametrize(
    ("n", "fraction", "expected"),
    [(8, 0.0, []), (8, 0.25, [2, 6]), (8, 1.0, list(range(8))), (3, 0.5, [0, 2]), (24, 0.125, [4, 12, 20]),
     (8, 0.05, [])],
)
def test_still_view_indices(n, fraction, expected):
    # n_still = round(f·V) (halves up), view ⌊(i + ½)·V/n_still⌋
    assert still_view_indices(n, fraction).tolist() == expected


def _path(overrides):
    p = resolve_params("toy", ("test", overrides))
    path, _ = build_path(p, get_spec("toy"), np.random.default_rng(7))
    return p, path


def test_default_path_is_orbit_times_shake():
    """still_views = 0 (the default, or given): the path is base(t)·shake(t) exactly, as before the option."""
    for overrides in ({}, {"still_views": 0.0}):
        _, path = _path(overrides)
        t = path.timeline.all_frame_times()
        assert path.still is None
        assert np.array_equal(path(t), path.base(t.astype(np.float64)) @ path.shake.offsets(t.astype(np.float64)))


def test_still_path_freezes_and_rejoins():
    _, ref = _path({})
    p, path = _path({"still_views": 0.25})
    tl = path.timeline
    assert np.flatnonzero(path.still).tolist() == STILL
    for v in range(tl.n_views):
        et = tl.exposure_frame_times(v)
        if v in STILL:  # every sub-frame pose is the start pose, bit for bit; the start pose is unchanged
            assert np.array_equal(path(et), np.broadcast_to(path(et[:1]), (et.size, 4, 4)))
            assert np.array_equal(path(et[:1]), ref(et[:1]))
            assert not np.allclose(ref(et), ref(et[:1]))  # without the option this exposure moves
        else:  # other views shake exactly as without the option
            assert np.array_equal(path(et), ref(et))
    # the shake clock is continuous and monotone: s(end_v) = start_v, s(start_{v+1}) = start_{v+1}
    t = np.arange(0, tl.exposures[-1, 1] + 1, 250, dtype=np.float64)
    s = path.shake_time(t)
    assert np.all(np.diff(s) >= 0) and np.diff(s).max() <= 250 * tl.period_us / (tl.period_us - tl.exposure_us) + 1e-6
    for v in STILL:
        start, end = tl.exposures[v]
        assert path.shake_time(np.array([end]))[0] == start
        assert path.shake_time(np.array([tl.starts[v + 1]]))[0] == tl.starts[v + 1]
    # the last view still: held to the stream end, finite
    _, last = _path({"still_views": 1.0})
    et = last.timeline.exposure_frame_times(tl.n_views - 1)
    assert np.array_equal(last(et), np.broadcast_to(last(et[:1]), (et.size, 4, 4)))
    assert np.isfinite(last(t)).all()


@pytest.mark.parametrize("value", [-0.1, 1.5, "half"])
def test_bad_still_views_is_a_clear_error(value):
    with pytest.raises(EigsError, match="still_views"):
        resolve_params("toy", ("test", {"still_views": value}))


def test_explicit_zero_generates_the_same_scene():
    small = {"n_train": 3, "n_novel": 1, "width": 24, "height": 18, "subframes": 8, "exposure_us": 16_000,
             "period_us": 32_000, "gap_subframes": 8, "lead_us": 2_000}
    a = generate("toy", small, show_progress=False).scene
    b = generate("toy", {**small, "still_views": 0.0}, show_progress=False).scene
    for x, y in [(a.frames.blurry, b.frames.blurry), (a.events.t, b.events.t), (a.events.x, b.events.x),
                 (a.events.p, b.events.p), (a.trajectory.c2w, b.trajectory.c2w), (a.sharp.images, b.sharp.images)]:
        assert np.array_equal(x, y)


@pytest.fixture(scope="module")
def still_scene():
    return generate("toy", {**FAST, "still_views": 0.25}, show_progress=False)


def test_still_frames_and_events(still_scene):
    g = still_scene
    s = g.scene
    assert g.stats["still_views"] == STILL
    n_px = s.camera.width * s.camera.height
    counts = np.diff(s.events.view_index, axis=1)[:, 0]
    p = g.params
    # sensor noise only: shot noise + leak at ~(shot + leak)·T events per pixel; moving views have ≫ 1
    noise = (p["shot_noise_hz"] + p["leak_rate_hz"]) * p["exposure_us"] * 1e-6 * n_px
    for v in range(p["n_train"]):
        if v in STILL:
            assert np.array_equal(s.frames.blurry[v], s.sharp.images[v])  # the blurry frame is the sharp frame
            assert counts[v] <= 2 * noise + 5
        else:
            assert not np.array_equal(s.frames.blurry[v], s.sharp.images[v])
            assert counts[v] > 1.0 * n_px


def test_still_exposures_without_sensor_noise_have_no_events():
    g = generate("toy", {**FAST, "still_views": 0.25, "shot_noise_hz": 0.0, "leak_rate_hz": 0.0, "width": 32,
                         "height": 24}, show_progress=False)
    ev = g.scene.events
    ex = g.scene.frames.exposure_us
    for v in STILL:
        a, b = ev.view_index[v]
        assert b == a  # a still exposure: identical sub-frames, no threshold crossing
        gap = (ev.t >= ex[v, 1]) & (ev.t < ex[v + 1, 0])
        assert gap.sum() > 0  # the camera moves on between exposures: those events are simulated


def test_edi_marks_exactly_the_still_views_sharp(still_scene):
    r = compute_edi(still_scene.scene, EdiOptions(show_progress=False))
    assert np.flatnonzero(r.sharp).tolist() == STILL
    # a sharp view's latent frames are its blurry frame (decoded), all B + 1 of them
    for v in STILL:
        assert np.allclose(r.latent[v], still_scene.scene.frames.blurry[v][None] / 255.0, atol=1e-6)
