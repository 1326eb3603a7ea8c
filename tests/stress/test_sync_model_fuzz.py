"""Readers of issue 33 parts 4 and 5 under damaged input: the frame→event homography file, the time-offset option,
and an existing COLMAP model (binary and text, every file truncated or with a flipped byte). Each either returns a
valid result or raises one :class:`~eigs.errors.EigsError` whose single-line message names the file; never another
exception or a crash (COLMAP's reader aborts the process on some damaged files: the stage probes it in a child)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from eigs.errors import EigsError
from tests.stress.budget import stress


def _one_line_naming(err: EigsError, path: Path | str | None) -> None:
    msg = str(err)
    assert "\n" not in msg, msg
    if path is not None:
        assert msg.startswith(f"{path}: "), msg


@stress(60)
@given(st.one_of(st.binary(max_size=200), st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=12)))
def test_homography_file(tmp_path_factory, content):
    from eigs.ingest.sync import parse_homography

    path = tmp_path_factory.mktemp("h") / "H.txt"
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(" ".join(repr(v) for v in content))
    try:
        H = parse_homography(path)
    except EigsError as err:
        _one_line_naming(err, path)
        return
    assert H.shape == (3, 3) and np.all(np.isfinite(H)) and abs(np.linalg.det(H)) > 0


@stress(100)
@given(st.text(max_size=40))
def test_time_offset_option(text):
    from eigs.ingest.sync import parse_time_offset

    try:
        got = parse_time_offset(text)
    except EigsError as err:
        _one_line_naming(err, "--time-offset-us")
        return
    assert isinstance(got, int) or (got[0] == "auto" and (got[1] is None or got[1][0] <= got[1][1]))


@pytest.fixture(scope="module")
def model_case(tmp_path_factory):
    """A named scene, its EDI and a matching COLMAP model written by pycolmap (binary and text)."""
    from tests.sfm.test_model_mode import build_case

    return build_case(tmp_path_factory.mktemp("model"))


def _files(model_case, layout: str) -> list[str]:
    return sorted(p.name for p in (model_case["dir"] / layout).iterdir())


# every file of the model damaged one at a time (each case reads the model in a child process: about a second)
@pytest.mark.parametrize(
    ("layout", "damage"),
    [("model", "truncate 0.3"), ("model", "flip 0.6"), ("model", "empty"), ("model_txt", "truncate 0.5"),
     ("model_txt", "missing")],
)  # fmt: skip
def test_damaged_colmap_model(model_case, tmp_path, layout, damage):
    from eigs.scene import read_scene
    from eigs.sfm.model import model_poses

    d = model_case["dir"]
    scene = read_scene(d / "scene.h5", events=False)
    for name in _files(model_case, layout):
        target = tmp_path / f"{name}-{damage.replace(' ', '_')}"
        shutil.copytree(d / layout, target)
        f = target / name
        data = f.read_bytes()
        kind, *arg = damage.split()
        if kind == "empty":
            data = b""
        elif kind == "truncate":
            data = data[: int(len(data) * float(arg[0]))]
        elif kind == "flip" and data:
            b = bytearray(data)
            b[int(len(b) * float(arg[0]))] ^= 0xFF
            data = bytes(b)
        if kind == "missing":
            f.unlink()
        else:
            f.write_bytes(data)
        try:
            mp = model_poses(target, scene, model_case["ts"], np.zeros(len(model_case["starts"]), bool), 0.01)
        except EigsError as err:
            _one_line_naming(err, target)
            continue
        assert np.all(np.isfinite(mp.latent_c2w))
        R = mp.c2w[:, :3, :3]
        np.testing.assert_allclose(R @ np.swapaxes(R, 1, 2), np.broadcast_to(np.eye(3), R.shape), atol=1e-6)
