"""Fuzzed recordings for the binary ingest readers of issue #33 (Prophesee RAW/DAT, AEDAT 2.0/3.1, NumPy; ROS
bags are in :mod:`tests.stress.test_rosbag_fuzz`): truncated or corrupted bytes give either a valid scene or one
:class:`~eigs.errors.EigsError` whose single line starts with the file's path — never another exception — and no
output file (complete or partial) after an error. Same damage model as :mod:`tests.stress.test_readers_fuzz`."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from eigs.errors import EigsError
from eigs.ingest import ingest
from eigs.ingest.options import IngestOptions
from eigs.scene import read_scene
from tests.stress.budget import stress
from tests.stress.test_readers_fuzz import Originals, assert_one_line_naming, damage, mutations

W, H = 64, 48


def _events(n=400, seed=0):
    rng = np.random.default_rng(seed)
    t = 1000 + np.cumsum(rng.integers(0, 30, n)).astype(np.int64)
    return rng.integers(0, W, n), rng.integers(0, H, n), t, rng.integers(0, 2, n)


@pytest.fixture(scope="module")
def recordings(tmp_path_factory) -> Originals:
    """format name → (file name, bytes) of a small valid recording, plus the options to ingest it."""
    from tests.ingest.prophesee_writer import known_events, write_dat, write_raw
    from tests.ingest.test_aedat_legacy import _events as aedat_events
    from tests.ingest.test_aedat_legacy import write_aedat20, write_aedat31

    root = tmp_path_factory.mktemp("rec")
    out = Originals()
    ev = known_events(400, W, H, t0=1000, seed=1)
    for enc in ("evt2", "evt21", "evt3"):
        write_raw(root / f"{enc}.raw", enc, *ev, W, H)
        out[enc] = (f"{enc}.raw", (root / f"{enc}.raw").read_bytes())
    write_dat(root / "rec.dat", *ev, W, H)
    out["dat"] = ("rec.dat", (root / "rec.dat").read_bytes())
    a = aedat_events(300, 240, 180)
    write_aedat31(root / "a31.aedat", a, [])
    out["aedat31"] = ("a31.aedat", (root / "a31.aedat").read_bytes())
    write_aedat20(root / "a20.aedat", a)
    out["aedat20"] = ("a20.aedat", (root / "a20.aedat").read_bytes())
    img = np.random.default_rng(2).integers(0, 256, (180, 240), dtype=np.uint8)
    write_aedat20(root / "aps.aedat", a, frames=[(int(a[2][200]), int(a[2][250]), img)])
    out["aedat20aps"] = ("aps.aedat", (root / "aps.aedat").read_bytes())
    x, y, t, p = _events()
    np.savez_compressed(root / "ev.npz", x=x, y=y, t=t, p=p)
    out["npz"] = ("ev.npz", (root / "ev.npz").read_bytes())
    np.save(root / "ev.npy", np.stack([t, x, y, p], 1))
    out["npy"] = ("ev.npy", (root / "ev.npy").read_bytes())
    return out


FORMATS = {
    "evt2": ("prophesee", {}),
    "evt21": ("prophesee", {}),
    "evt3": ("prophesee", {}),
    "dat": ("prophesee", {}),
    "aedat31": ("aedat", {}),
    "aedat20": ("aedat", {}),
    "aedat20aps": ("aedat", {}),
    "npz": ("numpy", {"time_unit": "us", "sensor_size": (W, H)}),
    "npy": ("numpy", {"time_unit": "us", "sensor_size": (W, H), "columns": "t,x,y,p"}),
}


def _check(name: str, recordings, mutation, directory: Path) -> None:
    fname, data = recordings[name]
    path = directory / fname
    path.write_bytes(damage(data, mutation))
    out = directory / "scene.h5"
    out.unlink(missing_ok=True)
    fmt, kw = FORMATS[name]
    opts = IngestOptions(intrinsics="50,50,32,24", keep_events="all", **kw)
    try:
        ingest(fmt, str(path), str(out), opts)
    except EigsError as err:
        if not str(err).startswith("--"):
            assert_one_line_naming(err, path)
        assert not out.exists()
        return
    read_scene(out)  # what was written is a valid scene


@pytest.mark.parametrize("name", list(FORMATS))
def test_truncated_recordings(name, recordings, tmp_path_factory):
    size = len(recordings[name][1])
    directory = tmp_path_factory.mktemp(name)
    for frac in (0.0, 0.01, 0.1, 0.5, 0.9, 0.999):
        _check(name, recordings, ("truncate", int(frac * size), b""), directory)


def _fuzz(name: str):
    @stress(30)
    @given(data=st.data())
    def run(recordings, tmp_path_factory, data) -> None:
        mutation = data.draw(mutations(len(recordings[name][1])), label="mutation")
        _check(name, recordings, mutation, tmp_path_factory.mktemp(name))

    return run


test_fuzz_evt2 = _fuzz("evt2")
test_fuzz_evt21 = _fuzz("evt21")
test_fuzz_evt3 = _fuzz("evt3")
test_fuzz_dat = _fuzz("dat")
test_fuzz_aedat31 = _fuzz("aedat31")
test_fuzz_aedat20 = _fuzz("aedat20")
test_fuzz_aedat20aps = _fuzz("aedat20aps")
test_fuzz_npz = _fuzz("npz")
test_fuzz_npy = _fuzz("npy")
