"""The generator: scene content and time base, zero shake, determinism, events vs rendered log change, blur
extent, parameter validation, textures, contact sheet."""

from __future__ import annotations

import numpy as np
import pytest

from eigs.errors import EigsError
from eigs.scene import read_scene, write_scene
from eigs.synth.generate import blur_extent, generate, intrinsics, write_generated
from eigs.synth.response import decode, encode
from eigs.synth.scenes import DEFAULTS, SCENE_NAMES, get_spec, resolve_params
from eigs.synth.simulator import log_luma
from eigs.synth.trajectory import look_at, so3_exp

# a fast variant of the toy scene: 3 + 2 views, 16 sub-frames per 16 ms exposure
SMALL = {
    "n_train": 3, "n_novel": 2, "subframes": 16, "exposure_us": 16_000, "period_us": 32_000, "gap_subframes": 8,
    "lead_us": 2_000, "lead_subframes": 2, "width": 40, "height": 30,
}


@pytest.fixture(scope="module")
def small():
    return generate("toy", SMALL, show_progress=False)


def test_scene_content_and_time_base(small):
    s = small.scene
    p = small.params
    v, b = p["n_train"], p["n_bins"]
    assert s.synthetic and s.channels == 3 and s.camera_response == "linear"
    assert s.contrast_threshold == pytest.approx(0.2)
    assert s.frames.blurry.shape == (v, 30, 40, 3) and s.frames.blurry.dtype == np.uint8
    starts = p["lead_us"] + np.arange(v) * p["period_us"]
    assert np.array_equal(s.frames.exposure_us, np.stack([starts, starts + p["exposure_us"]], 1))
    # latent times: B + 1 evenly spaced from exposure start to end inclusive
    k = np.arange(b + 1)
    assert np.array_equal(s.poses.latent_t_us, starts[:, None] + k[None] * p["exposure_us"] // b)
    assert s.poses.source == "ground-truth" and s.poses.latent_c2w.shape == (v, b + 1, 4, 4)
    assert np.allclose(s.poses.latent_c2w.reshape(-1, 4, 4), small.path(s.poses.latent_t_us.ravel()))
    # K: principal point at the image centre, pixel centres at j + 0.5
    assert np.allclose(s.camera.K, intrinsics(40, 30, p["fov_deg"]))
    assert s.camera.K[0, 2] == 20.0 and s.camera.K[1, 2] == 15.0
    # events: sorted, cover the whole stream (also between exposures), view_index = exposure membership
    ev = s.events
    assert np.all(np.diff(ev.t) >= 0)
    assert ev.t[0] < starts[0] and np.any((ev.t >= starts[0] + p["exposure_us"]) & (ev.t < starts[1]))
    for i, (a, e) in enumerate(ev.view_index):
        assert np.all(ev.t[a:e] >= starts[i]) and np.all(ev.t[a:e] < starts[i] + p["exposure_us"])
    # trajectory: strictly increasing, contains every latent time, matches the path
    tr = s.trajectory
    assert np.all(np.diff(tr.t_us) > 0) and np.isin(s.poses.latent_t_us, tr.t_us).all()
    assert tr.t_us[0] == 0 and tr.t_us[-1] == starts[-1] + p["exposure_us"]
    # sharp ground truth: blur views at the first latent time, then novel views
    sh = s.sharp
    assert np.array_equal(sh.kind, [0, 0, 0, 1, 1]) and np.array_equal(sh.view, [0, 1, 2, -1, -1])
    assert np.array_equal(sh.t_us[:3], s.poses.latent_t_us[:, 0])
    assert np.allclose(sh.c2w[:3], s.poses.latent_c2w[:, 0])
    assert np.array_equal(sh.c2w[3:], small.novel_c2w)
    assert s.background.shape == (3,) and np.all((s.background >= 0) & (s.background <= 1))


def test_write_and_read_back(small, tmp_path):
    out = tmp_path / "scene.h5"
    sheet = tmp_path / "sheet.png"
    write_generated(small, out, contact_sheet=sheet)
    back = read_scene(out)
    assert np.array_equal(back.frames.blurry, small.scene.frames.blurry)
    assert np.array_equal(back.events.t, small.scene.events.t)
    assert back.camera_response == "linear" and back.synthetic
    import cv2

    img = cv2.imread(str(sheet))
    assert img is not None and img.shape[0] > 100 and img.shape[1] > 3 * 128
    # rows: blurry, sharp, events, novel → the sheet is not blank
    assert img.std() > 10


def test_streamed_events_write_the_scene_held_in_memory(small, tmp_path, monkeypatch):
    """`eigs synth -o` streams each chunk of events into the scene file as it is simulated (memory: one view's);
    the file must hold exactly the scene that generation in memory gives, view index and contact sheet included,
    and no chunk may be held back until the end."""
    import json

    import cv2

    from eigs.cli import main
    from eigs.scene import SceneWriter
    from eigs.synth.contact_sheet import contact_sheet

    appended: list[int] = []
    original = SceneWriter.append_events

    def spy(self, x, y, t, p):
        appended.append(int(t.shape[0]))
        return original(self, x, y, t, p)

    monkeypatch.setattr(SceneWriter, "append_events", spy)
    out, sheet = tmp_path / "s.h5", tmp_path / "sheet.png"
    assert main(["synth", "--scene", "toy", "--overrides", json.dumps(SMALL), "-o", str(out),
                 "--contact-sheet", str(sheet)]) == 0
    ref = small.scene
    back = read_scene(out)
    assert len(appended) > 3 * 16 and sum(appended) == len(ref.events)  # one append per simulated step
    for name in ("x", "y", "t", "p", "view_index"):
        assert np.array_equal(getattr(back.events, name), getattr(ref.events, name)), name
    assert np.array_equal(small.view_index, ref.events.view_index)
    assert np.array_equal(back.frames.blurry, ref.frames.blurry)
    assert np.array_equal(back.sharp.images, ref.sharp.images)
    assert np.array_equal(back.trajectory.c2w, ref.trajectory.c2w)
    expected = contact_sheet(ref)
    assert np.array_equal(cv2.imread(str(sheet))[..., ::-1], expected)


def test_event_sink_keeps_no_events_and_counts_them(small):
    got: list[np.ndarray] = []
    g = generate("toy", SMALL, show_progress=False, event_sink=lambda c: got.append(c.t))
    assert g.scene.events is None
    t = np.concatenate(got)
    assert np.array_equal(t, small.scene.events.t)
    assert g.stats["events"] == t.shape[0] and np.array_equal(g.view_index, small.view_index)


def test_deferred_header_must_come_with_the_events_camera(small, tmp_path):
    from eigs.scene import Camera, SceneWriter

    ref = small.scene
    header = type(ref)(**{**ref.__dict__, "events": None})
    other = Camera(K=ref.camera.K * np.array([[2.0], [2.0], [1.0]]), width=ref.camera.width,
                   height=ref.camera.height)
    path = tmp_path / "x.h5"
    with pytest.raises(EigsError, match="not the one the events were written for"), \
            SceneWriter(path, None, camera=other) as w:
        w.append_events(ref.events.x, ref.events.y, ref.events.t, ref.events.p)
        w.set_header(header)
    with pytest.raises(RuntimeError, match="set_header"), SceneWriter(path, None, camera=ref.camera) as w:
        w.append_events(ref.events.x, ref.events.y, ref.events.t, ref.events.p)
    assert list(tmp_path.iterdir()) == [], "a failed write must leave nothing behind"


def test_zero_shake_gives_blurry_equal_to_sharp():
    g = generate("toy", {**SMALL, "shake": 0.0, "shot_noise_hz": 0.0, "leak_rate_hz": 0.0}, show_progress=False)
    s = g.scene
    blur_gt = s.sharp.images[s.sharp.kind == 0]
    assert np.array_equal(s.frames.blurry, blur_gt)
    # the camera does not move during an exposure → no events inside exposures
    assert np.all(s.events.view_index[:, 1] == s.events.view_index[:, 0])
    assert np.all(g.blur_px < 1e-6)


def test_deterministic_for_a_seed():
    a = generate("toy", {**SMALL, "seed": 5}, show_progress=False).scene
    b = generate("toy", {**SMALL, "seed": 5}, show_progress=False, threads=2).scene
    for x, y in ((a.frames.blurry, b.frames.blurry), (a.events.t, b.events.t), (a.events.x, b.events.x),
                 (a.events.p, b.events.p), (a.trajectory.c2w, b.trajectory.c2w), (a.sharp.images, b.sharp.images)):
        assert np.array_equal(x, y)
    c = generate("toy", {**SMALL, "seed": 6}, show_progress=False).scene
    assert not np.array_equal(a.trajectory.c2w, c.trajectory.c2w)
    assert len(a.events) != len(c.events) or not np.array_equal(a.events.t, c.events.t)


def test_exposure_events_match_rendered_log_change():
    """Ideal sensor, reference reset at each exposure start: |Σ signed − ΔL/C| < 1 at every pixel of every view,
    with ΔL from re-rendering the exposure's first and last sub-frames."""
    ideal = {"threshold_sigma": 0.0, "refractory_us": 0.0, "shot_noise_hz": 0.0, "leak_rate_hz": 0.0,
             "reset_at_exposure": True}
    g = generate("toy", {**SMALL, **ideal}, show_progress=False)
    s, p = g.scene, g.params
    w, h = s.camera.width, s.camera.height
    for v, (a, e) in enumerate(s.events.view_index):
        start, end = s.frames.exposure_us[v]
        rgb = g.caster.render(g.path(np.array([start, end])), s.camera.K, w, h, supersample=p["supersample"]).rgb
        dl = log_luma(rgb[1]) - log_luma(rgb[0])
        net = np.zeros((h, w))
        np.add.at(net, (s.events.y[a:e], s.events.x[a:e]), s.events.p[a:e].astype(float))
        assert np.all(np.abs(net - dl / p["contrast_threshold"]) < 1.0), v
        assert np.abs(dl).max() > 1.0  # the check is not vacuous


def test_blur_extent_closed_form():
    """Pure yaw θ about the camera centre: a point on the optical axis moves to f·tan θ from the centre."""
    K = intrinsics(64, 48, 40.0)
    c2w0 = np.eye(4)
    depth = np.full((48, 64), np.inf)
    depth[24, 32] = 3.0  # the pixel whose centre is (32.5, 24.5)
    theta = np.deg2rad(np.array([0.0, 0.5, 1.0, 2.0]))
    poses = np.repeat(np.eye(4)[None], theta.size, axis=0)
    poses[:, :3, :3] = so3_exp(np.stack([np.zeros_like(theta), theta, np.zeros_like(theta)], 1))
    ext = blur_extent(depth, K, c2w0, poses)
    assert ext.shape == (1,)
    # the point's projection at yaw θ: u = cx + f·tan(atan(x0/f) − θ) with x0 = 0.5 px off centre
    f = K[0, 0]
    u = K[0, 2] + f * np.tan(np.arctan(0.5 / f) - theta)
    assert ext[0] == pytest.approx(u.max() - u.min(), rel=1e-6)


def test_look_at_is_opencv():
    m = look_at(np.array([[4.0, 0.0, 0.0]]), np.zeros(3))[0]
    assert np.allclose(m[:3, 2], [-1, 0, 0])  # z forward, towards the target
    assert np.allclose(m[:3, 1], [0, 0, -1])  # y down
    assert np.allclose(np.linalg.det(m[:3, :3]), 1.0)


@pytest.mark.parametrize(
    "overrides, match",
    [
        ({"nope": 1}, "unknown parameter"),
        ({"width": "big"}, "must be a number"),
        ({"width": 0}, "width must be"),
        ({"subframes": 30}, "multiple of n_bins"),
        ({"subframes": 48}, "multiple of"),
        ({"period_us": 50_000}, "period_us must exceed"),
        ({"camera_response": "gamma"}, "camera_response"),
        ({"n_train": 2.5}, "integer"),
        ({"shake": -1}, "shake must be"),
        ({"reset_at_exposure": 1}, "true or false"),
    ],
)
def test_bad_overrides_are_clear_errors(overrides, match):
    with pytest.raises(EigsError, match=match):
        resolve_params("toy", ("--overrides", overrides))


def test_unknown_scene():
    with pytest.raises(EigsError, match="unknown built-in scene"):
        get_spec("lego")


def test_builtin_scene_defaults():
    assert set(SCENE_NAMES) == {"toy", "blocks", "chair", "tree", "dish", "spheres", "drums"}
    for name in SCENE_NAMES:
        p = resolve_params(name)
        want = (64, 48, 8, 4) if name == "toy" else (128, 96, 24, 12)
        assert (p["width"], p["height"], p["n_train"], p["n_novel"]) == want
        assert p["subframes"] >= 64
        assert get_spec(name).build()  # geometry builds
    assert DEFAULTS["contrast_threshold"] == 0.2 and DEFAULTS["threshold_sigma"] == 0.03


def test_srgb_response_round_trip(tmp_path):
    g = generate("toy", {**SMALL, "camera_response": "srgb", "n_train": 1, "n_novel": 0}, show_progress=False)
    assert g.scene.camera_response == "srgb"
    write_scene(g.scene, tmp_path / "s.h5")
    x = np.linspace(0, 1, 256)
    assert np.abs(decode(encode(x, "srgb"), "srgb") - x).max() < 0.01
    assert np.array_equal(encode(x, "linear"), np.round(x * 255).astype(np.uint8))


def test_textures_are_bundled_and_linear():
    from eigs.synth.textures import TEXTURE_NAMES, load_texture
    from eigs.util.image import linear_to_srgb, srgb_to_linear

    for name in TEXTURE_NAMES:
        t = load_texture(name, 32)
        assert t.shape == (32, 32, 3) and t.dtype == np.float32 and 0 <= t.min() and t.max() <= 1
        assert t.std() > 0.01  # a photograph, not a flat colour
    x = np.linspace(0, 1, 101)
    assert np.allclose(linear_to_srgb(srgb_to_linear(x)), x, atol=1e-12)
    assert srgb_to_linear(np.array([0.5]))[0] == pytest.approx(0.21404, abs=1e-4)


def test_texture_crop_is_a_window_of_the_photograph():
    # camera is 512×512: the window (0.5, 0.25, 0.25) is rows 128–255, columns 256–383 of the photograph
    import skimage.data
    from skimage.transform import resize

    from eigs.synth.textures import load_texture
    from eigs.util.image import srgb_to_linear

    raw = skimage.data.camera().astype(np.float64) / 255.0
    ref = srgb_to_linear(resize(raw[128:256, 256:384], (32, 32), order=1, anti_aliasing=True, mode="reflect"))
    got = load_texture("camera", 32, (0.5, 0.25, 0.25))
    assert np.abs(got[:, :, 0] - ref).max() < 1e-6
    assert not np.allclose(got, load_texture("camera", 32, (0.0, 0.0, 0.25)))
    for bad in [(0.0, 0.0, 0.0), (0.8, 0.0, 0.5), (0.0, -0.1, 0.5)]:
        with pytest.raises(EigsError, match="crop"):
            load_texture("camera", 32, bad)


def test_texture_offset_shifts_the_lookup():
    from eigs.synth.raycast import Box, Material, RayCaster

    def render(offset):
        box = Box((0.0, 0.0, 0.0), Material("astronaut", tile=4.0, offset=offset), half=(1.0, 1.0, 0.05))
        c2w = np.eye(4)
        c2w[:3, :3] = np.diag([1.0, -1.0, -1.0])  # looking down at the top face
        c2w[:3, 3] = (0.0, 0.0, 3.0)
        K = np.array([[40.0, 0, 16], [0, 40.0, 16], [0, 0, 1]])
        return RayCaster([box]).render(c2w, K, 32, 32, supersample=1).rgb[0]

    a, b = render((0.0, 0.0)), render((0.25, 0.0))
    assert not np.allclose(a, b)
    # a shift by one whole mirrored period (2 repeats) changes nothing
    assert np.allclose(a, render((2.0, 0.0)), atol=1e-5)


def test_room_shows_each_photograph_window_once():
    from eigs.synth.raycast import Patchwork
    from eigs.synth.scenes import SCENES, _environment

    room = _environment(-1.0, 3)
    floor = [p for p in room if isinstance(p, Patchwork)]
    assert len(floor) == 1 and len(floor[0].cells) == 36 and len(room) == 1 + 8
    keys = [(m.texture, m.crop) for m in floor[0].cells] + [(p.material.texture, p.material.crop) for p in room[1:]]
    assert len(set(keys)) == len(keys) == 44
    # every benchmark scene stands in a room; toy does not
    for name, spec in SCENES.items():
        assert sum(isinstance(p, Patchwork) for p in spec.build()) == (0 if name == "toy" else 1), name


def test_patchwork_floor_renders_like_its_cells_as_boxes():
    """The one-primitive floor shows exactly what n² flat boxes with centred texture windows show."""
    from eigs.synth.raycast import Box, Material, Patchwork, RayCaster
    from eigs.synth.trajectory import look_at

    n, half, z = 3, 1.5, -0.2
    side = 2 * half / n
    names = ["astronaut", "camera", "chelsea", "coffee", "coins", "hubble", "ihc", "moon", "retina"]
    cells = tuple(Material(t, (0.9, 0.7 + 0.03 * i, 0.6), side / 0.9, (0.5 * (i % 2), 0.0, 0.5))
                  for i, t in enumerate(names))  # fmt: skip
    boxes = [
        Box((-half + (i + 0.5) * side, -half + (j + 0.5) * side, z - 1e-4),
            Material(m.texture, m.tint, m.tile, m.crop, (-0.24, 0.08)), half=(side / 2, side / 2, 1e-4))
        for idx, m in enumerate(cells) for i, j in [divmod(idx, n)]
    ]  # fmt: skip
    c2w = look_at(np.array([[2.5, -1.5, 2.0], [0.3, 2.8, 1.2]]), np.array([0.0, 0.0, z]))
    K = np.array([[60.0, 0, 32], [0, 60.0, 24], [0, 0, 1]])
    a = RayCaster([Patchwork((0.0, 0.0, z), cells[0], half=half, cells=cells)]).render(c2w, K, 64, 48).rgb
    b = RayCaster(boxes).render(c2w, K, 64, 48).rgb
    differ = np.abs(a - b).max(axis=-1) > 1e-4
    assert differ.mean() < 0.005  # only where a ray grazes the (1e-4 thin) boxes' sides at the floor's edge
    assert np.abs(a - b).max(axis=-1)[~differ].max() < 1e-4
