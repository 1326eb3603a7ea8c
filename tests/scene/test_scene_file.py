"""Scene file v1: round trips, every validation rule, atomic writes."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from eigs.errors import EigsError
from eigs.scene import (
    BinnedEvents,
    Camera,
    Events,
    Frames,
    Poses,
    Scene,
    SceneWriter,
    SharpImages,
    Trajectory,
    read_events,
    read_scene,
    summarize,
    write_scene,
)

W, H, V, L = 16, 12, 3, 5


def rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def pose(a: float, t: float) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = rot_z(a)
    m[:3, 3] = [t, 2 * t, -t]
    return m


def make_scene(*, raw: bool = True, binned: bool = False, frames: bool = True, gt: bool = True) -> Scene:
    rng = np.random.default_rng(0)
    K = np.array([[20.0, 0, 8.0], [0, 21.0, 6.0], [0, 0, 1]])
    exposure = np.array([[1000 * v, 1000 * v + 500] for v in range(V)], dtype=np.int64)
    scene = Scene(
        name="unit",
        camera=Camera(K=K, width=W, height=H, distortion=np.zeros(5)),
        channels=3,
        camera_response="linear",
        synthetic=True,
        background=np.array([0.0, 0.5, 1.0]),
        contrast_threshold=0.2,
        source="unit test",
    )
    if frames:
        scene.frames = Frames(rng.integers(0, 256, (V, H, W, 3), dtype=np.uint8), exposure)
    if raw:
        n = 500
        t = np.sort(rng.integers(0, 3000, n)).astype(np.int64)
        scene.events = Events(
            rng.integers(0, W, n).astype(np.uint16),
            rng.integers(0, H, n).astype(np.uint16),
            t,
            rng.choice(np.array([-1, 1], np.int8), n),
            np.stack([np.searchsorted(t, exposure[:, 0]), np.searchsorted(t, exposure[:, 1])], 1).astype(np.int64)
            if frames
            else None,
        )
    if binned:
        edges = np.tile(np.array([0, 100, 200, 300, 400], np.int64), (V, 1))
        scene.binned = BinnedEvents(rng.integers(-5, 6, (V, 4, H, W)).astype(np.int32), edges)
    scene.poses = Poses(
        np.stack([np.stack([pose(0.1 * v + 0.01 * k, 0.2 * v) for k in range(L)]) for v in range(V)]),
        exposure[:, :1] + np.arange(L, dtype=np.int64) * 125,
        "ground-truth",
    )
    if gt:
        scene.trajectory = Trajectory(
            np.arange(0, 3000, 100, dtype=np.int64), np.stack([pose(0.001 * i, 0.0) for i in range(30)])
        )
        scene.sharp = SharpImages(
            rng.integers(0, 256, (4, H, W, 3), dtype=np.uint8),
            np.stack([pose(0.3 * i, 1.0) for i in range(4)]),
            np.array([0, 1000, 2000, 2500], np.int64),
            np.array([0, 0, 0, 1], np.uint8),
            np.array([0, 1, 2, -1], np.int64),
        )
    return scene


def assert_same(a: Scene, b: Scene) -> None:
    assert a.name == b.name and a.channels == b.channels and a.camera_response == b.camera_response
    assert a.synthetic == b.synthetic and a.source == b.source and a.contrast_threshold == b.contrast_threshold
    np.testing.assert_array_equal(a.camera.K, b.camera.K)
    assert (a.camera.width, a.camera.height) == (b.camera.width, b.camera.height)
    for part, fields in (
        ("frames", ("blurry", "exposure_us", "t_us")),
        ("events", ("x", "y", "t", "p", "view_index")),
        ("binned", ("counts", "bin_edges_us")),
        ("poses", ("latent_c2w", "latent_t_us")),
        ("trajectory", ("t_us", "c2w")),
        ("sharp", ("images", "c2w", "t_us", "kind", "view")),
    ):
        pa, pb = getattr(a, part), getattr(b, part)
        assert (pa is None) == (pb is None), part
        if pa is None:
            continue
        for fld in fields:
            va, vb = getattr(pa, fld), getattr(pb, fld)
            if va is None or vb is None:
                assert va is None and vb is None, f"{part}.{fld}"
                continue
            assert va.dtype == vb.dtype, f"{part}.{fld}"
            np.testing.assert_array_equal(va, vb, err_msg=f"{part}.{fld}")


@pytest.mark.parametrize(
    "kw",
    [
        {},
        {"raw": False, "binned": True},
        {"raw": True, "binned": True},
        {"frames": False, "raw": True},
        {"raw": False, "gt": False},
        {"frames": False, "raw": False, "gt": False},
    ],
)
@pytest.mark.parametrize("compression", [None, "gzip"])
def test_round_trip(tmp_path, kw, compression):
    scene = make_scene(**kw)
    path = tmp_path / "scene.h5"
    write_scene(scene, path, compression=compression)
    back = read_scene(path)
    assert_same(scene, back)
    assert "scene 'unit'" in summarize(back)


def test_frame_timestamps_round_trip_and_version_1_files(tmp_path):
    """Version 2 keeps frames/t_us for frames without exposure windows; a version 1 file (no t_us) still reads."""
    scene = make_scene(raw=False)
    scene.frames.exposure_us = None
    scene.frames.t_us = np.array([5, 40_000, 77_531], np.int64)
    path = tmp_path / "scene.h5"
    write_scene(scene, path)
    back = read_scene(path)
    assert_same(scene, back)
    assert "instants" in summarize(back)
    with h5py.File(path, "r") as f:
        assert int(f.attrs["version"]) == 2
    old = make_scene()
    write_scene(old, tmp_path / "v1.h5")
    with h5py.File(tmp_path / "v1.h5", "r+") as f:  # what version 1 wrote: the same layout without frames/t_us
        f.attrs["version"] = 1
    assert_same(old, read_scene(tmp_path / "v1.h5"))
    scene.frames.exposure_us = np.zeros((V, 2), np.int64)
    with pytest.raises(EigsError, match="frames/t_us is for frames without exposure windows"):
        write_scene(scene, tmp_path / "both.h5")
    scene.frames.exposure_us = None
    scene.frames.t_us = np.array([1, 2], np.int64)
    with pytest.raises(EigsError, match="frames/t_us has shape 2, expected 3"):
        write_scene(scene, tmp_path / "short.h5")


def test_read_events_slice_and_lazy_header(tmp_path):
    scene = make_scene()
    path = tmp_path / "scene.h5"
    write_scene(scene, path)
    part = read_events(path, 10, 20)
    np.testing.assert_array_equal(part.t, scene.events.t[10:20])
    assert read_scene(path, events=False).events is None


def test_streaming_writer_matches_one_shot(tmp_path):
    scene = make_scene()
    ev = scene.events
    header = Scene(**{**scene.__dict__, "events": None})
    path = tmp_path / "stream.h5"
    with SceneWriter(path, header) as w:
        for s in range(0, len(ev), 97):
            sl = slice(s, s + 97)
            w.append_events(ev.x[sl], ev.y[sl], ev.t[sl], ev.p[sl])
        w.set_view_index(ev.view_index)
    assert_same(scene, read_scene(path))


def test_empty_events_round_trip(tmp_path):
    scene = make_scene(raw=False)
    scene.events = Events.empty()
    scene.events.view_index = np.zeros((V, 2), np.int64)
    write_scene(scene, tmp_path / "e.h5")
    back = read_scene(tmp_path / "e.h5")
    assert len(back.events) == 0


# --- every validation rule, on write and on read --------------------------------------------------------


def _unsorted(s):
    s.events.t[5], s.events.t[6] = s.events.t[6] + 10, s.events.t[5]


def _set(attr_path, value):
    def f(s):
        obj = s
        *head, last = attr_path.split(".")
        for h in head:
            obj = getattr(obj, h)
        cur = getattr(obj, last)
        if callable(value):
            setattr(obj, last, value(cur))
        else:
            setattr(obj, last, value)

    return f


def _x_out(s):
    s.events.x[0] = W


def _y_out(s):
    s.events.y[3] = H + 5


def _bad_pol(s):
    s.events.p[2] = 0


def _nan_pose(s):
    s.poses.latent_c2w[1, 2, 0, 3] = np.nan


def _nonrigid(s):
    s.poses.latent_c2w[0, 0, :3, :3] *= 1.1


def _nan_K(s):
    s.camera.K[0, 2] = np.inf


def _exposure_back(s):
    s.frames.exposure_us[1] = [900, 800]


def _bad_index(s):
    s.events.view_index[1, 1] += 3


def _neg_time(s):
    s.events.t[:] -= 10_000


def _frames_size(s):
    s.frames.blurry = s.frames.blurry[:, :, :-1]


def _nan_traj(s):
    s.trajectory.c2w[3, 0, 0] = np.nan


def _nan_bg(s):
    s.background = np.array([0.0, np.nan, 1.0])


def _K_not_pinhole(s):
    s.camera.K[2] = [0.0, 0.0, 2.0]


def _bg_range(s):
    s.background = np.array([0.0, 0.5, 1.5])


def _unequal_events(s):
    s.events.x = s.events.x[:-1]


def _index_range(s):
    s.events.view_index[2, 1] = len(s.events) + 5


def _bin_edges(s):
    edges = np.tile(np.array([0, 100, 100, 300, 400], np.int64), (V, 1))
    s.binned = BinnedEvents(np.zeros((V, 4, H, W), np.int32), edges)


def _latent_t_back(s):
    s.poses.latent_t_us[1, 3] = s.poses.latent_t_us[1, 2] - 1


def _last_row(s):
    s.poses.latent_c2w[0, 1, 3, 0] = 0.5


def _sharp_view(s):
    s.sharp.view[2] = V


BAD = [
    (_unsorted, "not sorted in time"),
    (_neg_time, "negative timestamps"),
    (_x_out, "outside the 16×12 sensor"),
    (_y_out, "outside the 16×12 sensor"),
    (_bad_pol, "events/p must be ±1"),
    (_nan_pose, "NaN/Inf"),
    (_nonrigid, "not rigid"),
    (_nan_K, "camera/K has 1 NaN/Inf"),
    (_exposure_back, "ends (800 µs) before it starts (900 µs)"),
    (_bad_index, "does not cover the events of view 1"),
    (_frames_size, "frames/blurry has shape 3×12×15×3, expected ?×12×16×3"),
    (_nan_traj, "gt/trajectory/c2w has 1 NaN/Inf"),
    (_nan_bg, "background has 1 NaN/Inf"),
    (_set("camera_response", "log"), "camera_response must be one of"),
    (_set("channels", 2), "channels must be 1 or 3"),
    (_set("contrast_threshold", -0.1), "contrast_threshold must be a positive number"),
    (_set("poses.source", "guess"), "poses source must be one of"),
    (_set("sharp.kind", lambda k: k + 5), "gt/sharp/kind must be one of"),
    (_set("trajectory.t_us", lambda t: t[::-1].copy()), "strictly increasing"),
    (_set("events.t", lambda t: t.astype(np.float64)), "events/t has dtype float64, expected int64"),
    (_K_not_pinhole, "camera/K is not a pinhole intrinsic matrix"),
    (_set("camera.width", 0), "camera size must be positive, got 0×12"),
    (_bg_range, "background must lie in [0, 1]"),
    (_unequal_events, "events/x has 499 entries but events/t has 500"),
    (_index_range, "events/view_index has offsets outside [0, 500]"),
    (_bin_edges, "events/bin_edges_us must be strictly increasing"),
    (_latent_t_back, "poses/latent_t_us must be non-decreasing"),
    (_last_row, "last row of a pose is not [0 0 0 1]"),
    (_sharp_view, "gt/sharp/view must be −1 or a view index below 3"),
]


@pytest.mark.parametrize("mutate,message", BAD, ids=[m for _, m in BAD])
def test_validation_on_write(tmp_path, mutate, message):
    scene = make_scene()
    mutate(scene)
    path = tmp_path / "bad.h5"
    with pytest.raises(EigsError) as err:
        write_scene(scene, path)
    assert message in str(err.value)
    assert str(path) in str(err.value)
    assert list(tmp_path.iterdir()) == [], "a failed write must leave nothing behind"


def _write_unchecked(scene: Scene, path, monkeypatch) -> None:
    """Write ``scene`` with the writer's own layout but none of its checks, then the event arrays exactly as
    given (any length or dtype), as a file written by another tool might be."""
    import eigs.scene.file as scene_file

    for name in ("validate_header", "check_event_chunk", "check_view_index_sorted", "check_event_dtypes"):
        monkeypatch.setattr(scene_file, name, lambda *a, **k: None)
    ev = scene.events
    write_scene(Scene(**{**scene.__dict__, "events": None}), path)
    monkeypatch.undo()
    with h5py.File(path, "r+") as f:
        for name in ("x", "y", "t", "p", "view_index"):
            f.create_dataset(f"events/{name}", data=getattr(ev, name))
        f["events"].attrs["count"] = len(ev.t)


def test_unchecked_writer_writes_a_valid_scene_unchanged(tmp_path, monkeypatch):
    scene = make_scene()
    _write_unchecked(scene, tmp_path / "ok.h5", monkeypatch)
    assert_same(read_scene(tmp_path / "ok.h5"), scene)


@pytest.mark.parametrize("mutate,message", BAD, ids=[m for _, m in BAD])
def test_validation_on_read(tmp_path, monkeypatch, mutate, message):
    """The same mutated scenes written without any check (bypassing the writer's validation): the reader must
    refuse each with the same message."""
    scene = make_scene()
    mutate(scene)
    path = tmp_path / "scene.h5"
    _write_unchecked(scene, path, monkeypatch)
    with pytest.raises(EigsError) as err:
        read_scene(path)
    assert message in str(err.value)
    assert str(path) in str(err.value)


def test_failed_streaming_write_leaves_nothing(tmp_path):
    scene = make_scene()
    header = Scene(**{**scene.__dict__, "events": None})
    path = tmp_path / "s.h5"
    with pytest.raises(EigsError, match="not sorted"), SceneWriter(path, header) as w:
        w.append_events(scene.events.x[:10], scene.events.y[:10], scene.events.t[:10], scene.events.p[:10])
        w.append_events(scene.events.x[:10], scene.events.y[:10], scene.events.t[:10] - 1, scene.events.p[:10])
    assert list(tmp_path.iterdir()) == []


def test_exception_inside_writer_leaves_nothing(tmp_path):
    path = tmp_path / "s.h5"
    with pytest.raises(RuntimeError), SceneWriter(path, make_scene(raw=False)):
        raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []


def test_overwrite_keeps_old_file_on_failure(tmp_path):
    path = tmp_path / "s.h5"
    write_scene(make_scene(), path)
    before = path.read_bytes()
    bad = make_scene()
    _x_out(bad)
    with pytest.raises(EigsError):
        write_scene(bad, path)
    assert path.read_bytes() == before


def test_reader_errors(tmp_path):
    with pytest.raises(EigsError, match="no such scene file"):
        read_scene(tmp_path / "missing.h5")
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"not hdf5 at all")
    with pytest.raises(EigsError, match="not a readable HDF5 file"):
        read_scene(junk)
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f.attrs["format"] = "something-else"
    with pytest.raises(EigsError, match="not an eigs scene file"):
        read_scene(other)
    good = tmp_path / "good.h5"
    write_scene(make_scene(), good)
    with h5py.File(good, "r+") as f:
        f.attrs["version"] = 99
    with pytest.raises(EigsError, match="version 99 is not supported"):
        read_scene(good)
    trunc = tmp_path / "trunc.h5"
    write_scene(make_scene(), trunc)
    data = trunc.read_bytes()
    trunc.write_bytes(data[: len(data) // 2])
    with pytest.raises(EigsError):
        read_scene(trunc)


def test_require_names_missing_parts():
    scene = make_scene(raw=False, gt=False)
    scene.frames.exposure_us = None
    with pytest.raises(EigsError, match="the scene has no exposure, events .*--exposure-us"):
        scene.require("frames", "exposure", "events", hint="ingest with --exposure-us START,END")
