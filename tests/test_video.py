"""``eigs video`` and eigs.view.video: H.264 MP4 encoding with the ffmpeg binary of imageio-ffmpeg, read back by the
same binary (frame count, size, codec, content), side-by-side orbit videos of runs, atomic writes and one-line
errors. The runs are the tiny Gaussian scene of tests/test_view.py."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import imageio_ffmpeg
import numpy as np
import pytest

from eigs.errors import EigsError
from eigs.view.video import CAPTION_PX, VideoOptions, encode_mp4, even_frame, probe_mp4
from tests.test_view import H, W, make_view_case


def ramp_frames(n: int, w: int = 64, h: int = 48) -> list[np.ndarray]:
    """Frame i: grey level 20 + 20 i everywhere but a white square whose x position moves with i."""
    out = []
    for i in range(n):
        f = np.full((h, w, 3), 20 + 20 * i, np.uint8)
        f[8:24, 4 * i : 4 * i + 16] = 255
        out.append(f)
    return out


def decoded(path: Path) -> list[np.ndarray]:
    gen = imageio_ffmpeg.read_frames(str(path))
    meta = next(gen)
    w, h = meta["size"]
    return [np.frombuffer(b, np.uint8).reshape(h, w, 3) for b in gen]


def test_encode_round_trip_keeps_count_size_and_content(tmp_path):
    frames = ramp_frames(10)
    out = tmp_path / "v.mp4"
    assert encode_mp4(frames, out, fps=10) == 10
    info = probe_mp4(out)
    assert (info["frames"], info["width"], info["height"]) == (10, 64, 48)
    assert info["codec"].startswith("h264") and info["fps"] == pytest.approx(10.0)
    back = decoded(out)
    assert len(back) == 10
    for i, (a, b) in enumerate(zip(frames, back, strict=True)):
        # lossy, but each frame's grey level and its square's position survive (independent of the encoder's choice)
        assert abs(float(b[36:, :].mean()) - (20 + 20 * i)) < 4, i
        assert float(b[12:20, 4 * i + 4 : 4 * i + 12].mean()) > 230, i
        assert np.abs(a.astype(int) - b.astype(int)).mean() < 6
    assert sorted(p.name for p in tmp_path.iterdir()) == ["v.mp4"], "no temporary file left behind"


def test_even_frame_pads_odd_sizes_with_the_edge():
    f = np.arange(5 * 7 * 3, dtype=np.uint8).reshape(5, 7, 3)
    g = even_frame(f)
    assert g.shape == (6, 8, 3)
    assert np.array_equal(g[:5, :7], f) and np.array_equal(g[5, :7], f[4]) and np.array_equal(g[:5, 7], f[:, 6])
    assert even_frame(np.zeros((4, 6, 3), np.uint8)).shape == (4, 6, 3)


@pytest.mark.parametrize(
    "frames, name, message",
    [
        (ramp_frames(3), "v.avi", "ending in .mp4"),
        ([], "v.mp4", "no frames to encode"),
        ([np.zeros((48, 64, 3), np.uint8), np.zeros((48, 66, 3), np.uint8)], "v.mp4", "frame 1 is 66x48"),
        ([np.zeros((47, 64, 3), np.uint8)], "v.mp4", "needs an even width and height"),
        ([np.zeros((48, 64), np.float32)], "v.mp4", "expected (H, W, 3) uint8"),
    ],
)
def test_bad_frames_are_one_line_errors_and_leave_nothing(tmp_path, frames, name, message):
    with pytest.raises(EigsError) as err:
        encode_mp4(frames, tmp_path / name, fps=10)
    assert message in str(err.value) and "\n" not in str(err.value)
    assert list(tmp_path.iterdir()) == []


def test_probe_of_a_file_that_is_no_video_is_one_line(tmp_path):
    bad = tmp_path / "bad.mp4"
    bad.write_bytes(b"\x00\x01 not a video" * 100)
    with pytest.raises(EigsError) as err:
        probe_mp4(bad)
    assert str(err.value).startswith(f"{bad}: not a readable video") and "\n" not in str(err.value)


@pytest.fixture(scope="module")
def case(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    return make_view_case(tmp_path_factory.mktemp("video_case"))


def _eigs(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "eigs", *args], capture_output=True, text=True, timeout=timeout)


def test_cli_renders_runs_side_by_side(case, tmp_path):
    """Two runs (a picture and its colour negative) along 8 path cameras: 8 frames of two panels under the caption
    strip; the panels differ where the negative does."""
    out = tmp_path / "videos" / "case.mp4"
    res = _eigs("video", str(case["3dgs"]), str(case["eigs"]), "-o", str(out), "--frames", "8", "--fps", "8",
                "--threads", "1")  # fmt: skip
    assert res.returncode == 0, res.stderr
    info = probe_mp4(out)
    assert (info["frames"], info["width"], info["height"]) == (8, 2 * W, H + CAPTION_PX)
    first = decoded(out)[0]
    strip, left, right = first[:CAPTION_PX], first[CAPTION_PX:, :W], first[CAPTION_PX:, W:]
    assert strip.max() > 200 and float(strip.mean()) < 60, "white labels on black"
    assert np.abs(left.astype(int) - right.astype(int)).mean() > 10, "the two runs' panels differ"
    assert sorted(p.name for p in out.parent.iterdir()) == ["case.mp4"]
    assert "wrote" in res.stderr and "8 frames" in res.stderr


@pytest.mark.parametrize(
    "which, extra, message",
    [
        ("missing", [], "no such run folder"),
        ("3dgs", ["--frames", "0"], "needs at least one frame"),
        ("3dgs", ["--sfm", "NOSFM"], "no poses.h5"),
        ("field", [], "unreadable field model"),
    ],
)
def test_cli_errors_are_one_line(case, tmp_path, which, extra, message):
    run = tmp_path / "nope" if which == "missing" else case[which]
    extra = [str(tmp_path) if a == "NOSFM" else a for a in extra]
    out = tmp_path / "x.mp4"
    res = _eigs("video", str(run), "-o", str(out), *extra)
    assert res.returncode == 2, res.stderr
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("eigs video: error: ") and message in lines[0], res.stderr
    assert not out.exists()


def test_defaults():
    d = VideoOptions()
    assert (d.frames, d.fps) == (60, 20)
