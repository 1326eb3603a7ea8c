"""``blur_synthesis``: with ``e2nerf`` the blurry frame is E²NeRF's, the mean of 17 renders at k·T/16, k = 0..16, in
linear intensity, clamped, then the scene's display transform; the renderer is replaced by a stub whose render of
any pose is known, and the expected frame is computed here in float64, independently of the generator. The
latent times fall on renders 1, 5, 9, 13, 17; events, sharp ground truth and poses are those of the default; the
default (``average``, all sub-frames) is unchanged; a bad value or an incompatible ``subframes`` is a one-line error."""

from __future__ import annotations

import importlib

import numpy as np
import pytest

from eigs.cli import main
from eigs.errors import EigsError
from eigs.synth.blur import e2nerf_subframe_indices
from eigs.synth.generate import generate
from eigs.synth.raycast import RenderResult
from eigs.synth.scenes import resolve_params
from eigs.synth.trajectory import Timeline

generate_module = importlib.import_module("eigs.synth.generate")  # (eigs.synth.generate is also the function)

# 4 × 3 px, 3 + 1 views, 32 sub-frame intervals per exposure (33 renders: 17 of them are E²NeRF's)
TINY = {"width": 4, "height": 3, "n_train": 3, "n_novel": 1, "subframes": 32, "gap_subframes": 4,
        "lead_subframes": 1, "supersample": 1, "seed": 5}  # fmt: skip


def stub_image(c2w: np.ndarray, height: int, width: int) -> np.ndarray:
    """The stub renderer's image of each pose: (F, 4, 4) → (F, H, W, 3) float32 in [0.05, 0.95], a smooth pattern
    whose phase moves fast with the camera position and orientation, so every sub-frame differs."""
    c2w = np.asarray(c2w, np.float64).reshape(-1, 4, 4)
    phase = 400.0 * (c2w[:, 0, 3] + 2 * c2w[:, 1, 3] + 3 * c2w[:, 2, 3]) + 50.0 * c2w[:, 0, 0]  # (F,)
    i, j, c = np.meshgrid(np.arange(height), np.arange(width), np.arange(3), indexing="ij")
    rgb = 0.5 + 0.45 * np.sin(phase[:, None, None, None] + 0.9 * i + 0.4 * j + 1.3 * c)
    return rgb.astype(np.float32)


class StubCaster:
    """Stands in for :class:`eigs.synth.raycast.RayCaster`: renders :func:`stub_image`, depth 1 everywhere."""

    def __init__(self, *args, **kwargs) -> None:
        pass

    def render(self, c2w, K, width, height, *, supersample=2, want_depth=False, threads=1) -> RenderResult:
        rgb = stub_image(c2w, height, width)
        return RenderResult(rgb, np.ones(rgb.shape[:3], np.float32) if want_depth else None)


def srgb(x: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB encoding of linear x in [0, 1] (float64)."""
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def display_u8(linear: np.ndarray, response: str) -> np.ndarray:
    """The scene's 8-bit display encoding: ⌊255·y + ½⌋ of y = x (linear) or sRGB(x), x clamped to [0, 1]."""
    x = np.clip(linear, 0.0, 1.0)
    y = srgb(x) if response == "srgb" else x
    return np.floor(255.0 * y + 0.5).astype(np.uint8)


@pytest.fixture(scope="module", params=["linear", "srgb"])
def stubbed(request):
    """The tiny toy scene rendered by the stub, with ``average`` (explicit and default) and ``e2nerf``."""
    mp = pytest.MonkeyPatch()
    mp.setattr(generate_module, "RayCaster", StubCaster)
    try:
        p = {**TINY, "camera_response": request.param}
        runs = {
            "default": generate("toy", p, show_progress=False),
            "average": generate("toy", {**p, "blur_synthesis": "average"}, show_progress=False),
            "e2nerf": generate("toy", {**p, "blur_synthesis": "e2nerf"}, show_progress=False),
        }
    finally:
        mp.undo()
    return request.param, runs


def test_e2nerf_blur_is_the_mean_of_17_known_renders_then_the_display_transform(stubbed):
    response, runs = stubbed
    g = runs["e2nerf"]
    s = g.scene
    h, w, T = TINY["height"], TINY["width"], s.frames.exposure_us[0, 1] - s.frames.exposure_us[0, 0]
    for v in range(s.n_views):
        start = int(s.frames.exposure_us[v, 0])
        t17 = start + np.arange(17) * T // 16  # E²NeRF: first render at the exposure start, last at its end
        assert T % 16 == 0 and t17[-1] == s.frames.exposure_us[v, 1]
        renders = stub_image(g.path(t17), h, w).astype(np.float64)  # the 17 known renders
        expected = display_u8(renders.mean(axis=0), response)
        np.testing.assert_array_equal(s.frames.blurry[v], expected)
        # and not the mean of all 33 sub-frames: the test tells the two syntheses apart
        t33 = start + np.arange(33) * T // 32
        all33 = display_u8(stub_image(g.path(t33), h, w).astype(np.float64).mean(axis=0), response)
        assert not np.array_equal(all33, expected)
        np.testing.assert_array_equal(runs["default"].scene.frames.blurry[v], all33)  # the default: all of them
    assert s.source.endswith(", blur e2nerf)")


def test_latent_times_are_renders_1_5_9_13_17(stubbed):
    _, runs = stubbed
    s = runs["e2nerf"].scene
    starts, T = s.frames.exposure_us[:, 0], s.frames.exposure_us[0, 1] - s.frames.exposure_us[0, 0]
    t17 = starts[:, None] + np.arange(17)[None] * T // 16  # (V, 17)
    assert s.poses.latent_t_us.shape[1] == 5
    np.testing.assert_array_equal(s.poses.latent_t_us, t17[:, [0, 4, 8, 12, 16]])  # 1-based: 1, 5, 9, 13, 17
    # the same at the default time base (80 sub-frame intervals per 100 ms exposure, B = 4)
    p = resolve_params("toy", ("test", {"blur_synthesis": "e2nerf"}))
    tl = Timeline(p["n_train"], p["exposure_us"], p["period_us"], p["lead_us"], p["subframes"], p["gap_subframes"],
                  p["lead_subframes"])
    for v in range(p["n_train"]):
        et = tl.exposure_frame_times(v)
        e17 = et[e2nerf_subframe_indices(p["subframes"])]
        np.testing.assert_array_equal(e17, et[0] + np.arange(17) * p["exposure_us"] // 16)
        np.testing.assert_array_equal(tl.latent_times(p["n_bins"])[v], e17[[0, 4, 8, 12, 16]])


def test_only_the_blurry_frames_change_and_the_default_is_average(stubbed):
    _, runs = stubbed
    d, a, e = (runs[k].scene for k in ("default", "average", "e2nerf"))
    np.testing.assert_array_equal(d.frames.blurry, a.frames.blurry)  # the option off is the default
    assert d.source == a.source and ", blur" not in d.source
    for other in (a, e):  # the events, the sharp ground truth and the poses are the default's
        for name in ("t", "x", "y", "p"):
            np.testing.assert_array_equal(getattr(d.events, name), getattr(other.events, name))
        np.testing.assert_array_equal(d.sharp.images, other.sharp.images)
        np.testing.assert_array_equal(d.poses.latent_t_us, other.poses.latent_t_us)
        np.testing.assert_array_equal(d.poses.latent_c2w, other.poses.latent_c2w)
        np.testing.assert_array_equal(d.trajectory.c2w, other.trajectory.c2w)
    assert not np.array_equal(d.frames.blurry, e.frames.blurry)


def test_a_still_exposure_stays_its_sharp_frame():
    """No shake: all 17 renders are one image, and their float64 mean is that image bit for bit."""
    g = generate("toy", {**TINY, "width": 16, "height": 12, "shake": 0.0, "blur_synthesis": "e2nerf"},
                 show_progress=False)
    np.testing.assert_array_equal(g.scene.frames.blurry, g.scene.sharp.images[: g.scene.n_views])


@pytest.mark.parametrize(
    "overrides, message",
    [
        ('{"blur_synthesis": "sum"}', "blur_synthesis must be one of ('average', 'e2nerf'), got 'sum'"),
        ('{"blur_synthesis": "e2nerf", "subframes": 40}', "blur_synthesis e2nerf needs subframes a multiple of 16"),
    ],
)
def test_bad_values_are_one_line_errors(overrides, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["synth", "--scene", "toy", "--overrides", overrides, "-o", "x.h5"]) == 2
    err = capsys.readouterr().err
    assert message in err and err.startswith("eigs synth: error:") and err.count("\n") == 1
    assert not (tmp_path / "x.h5").exists()
    with pytest.raises(EigsError, match="blur_synthesis"):
        resolve_params("toy", ("test", {"blur_synthesis": 3}))


def test_the_option_is_listed(capsys):
    assert main(["synth", "--list"]) == 0
    out = capsys.readouterr().out
    assert "blur_synthesis = 'average'" in out and "e2nerf:  E²NeRF's: the mean of 17 renders" in out
