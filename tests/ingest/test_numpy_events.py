"""NumPy event arrays (``--format numpy``) written by the tests with np.save / np.savez(_compressed)."""

from __future__ import annotations

import numpy as np
import pytest

from eigs.scene import read_scene
from tests.ingest.conftest import expect_failure, run_ingest
from tests.ingest.fixtures import H, W, random_events, write_frames

K_OPT = "30,30,5,3"
SIZE = f"{W}x{H}"


def _check(out, ev, p=None):
    s = read_scene(out)
    np.testing.assert_array_equal(s.events.t, ev.t_us)
    np.testing.assert_array_equal(s.events.x, ev.x)
    np.testing.assert_array_equal(s.events.y, ev.y)
    np.testing.assert_array_equal(s.events.p, np.where(ev.p01 == 1, 1, -1) if p is None else p)
    return s


def test_npz_members_seconds(tmp_path):
    """EventNeRF-style npz: x, y, t, p members, t float seconds, p ±1; compressed members stream too."""
    ev = random_events(5000)
    f = tmp_path / "ev.npz"
    np.savez_compressed(f, x=ev.x, y=ev.y, t=ev.t_us / 1e6, p=np.where(ev.p01 == 1, 1, -1).astype(np.int8))
    out = tmp_path / "s.h5"
    opts = ("--time-unit", "s", "--sensor-size", SIZE, "--intrinsics", K_OPT)
    assert run_ingest("numpy", f, out, *opts) == 0
    _check(out, ev)
    # the same in chunks of 333 events (chunk boundaries inside the member streams)
    from eigs.ingest.numpy_events import plan_events, read_numpy_events

    plan, _, _ = plan_events(f, None)
    got = list(read_numpy_events(f, plan, "s", W, H, chunk=333))
    assert len(got) == -(-5000 // 333)
    np.testing.assert_array_equal(np.concatenate([c[2] for c in got]), ev.t_us)


def test_npy_columns_and_transposed(tmp_path):
    """Plain (N, 5) arrays need --columns (- skips a column); a (5, N) array and a Fortran-order one read the same."""
    ev = random_events(3000)
    a = np.stack([ev.x, ev.y, ev.t_us * 1000, ev.p01, np.zeros(3000)], axis=1).astype(np.float64)  # t in ns
    opts = ("--time-unit", "ns", "--sensor-size", SIZE, "--intrinsics", K_OPT, "--columns", "x,y,t,p,-")
    for name, arr in (("rows", a), ("cols", a.T.copy()), ("fortran", np.asfortranarray(a))):
        f = tmp_path / f"{name}.npy"
        np.save(f, arr)
        out = tmp_path / f"{name}.h5"
        assert run_ingest("numpy", f, out, *opts) == 0, name
        _check(out, ev)


def test_structured_with_frames_sidecar(tmp_path):
    ev = random_events(4000, t0=10_000)
    rec = np.zeros(4000, dtype=[("timestamp", "<i8"), ("x", "<u2"), ("y", "<u2"), ("polarity", "?")])
    rec["timestamp"], rec["x"], rec["y"], rec["polarity"] = ev.t_us, ev.x, ev.y, ev.p01.astype(bool)
    f = tmp_path / "rec.npy"
    np.save(f, rec)
    px, names = write_frames(tmp_path, 2)
    exposures = np.array([[11_000, 12_000], [20_000, 21_500]])
    (tmp_path / "rec.frames.txt").write_text(
        "".join(f"{a} {b} {n}\n" for (a, b), n in zip(exposures, names, strict=True))
    )
    out = tmp_path / "s.h5"
    assert run_ingest("numpy", f, out, "--time-unit", "us", "--intrinsics", K_OPT, "--keep-events", "all") == 0
    s = _check(out, ev)
    np.testing.assert_array_equal(s.frames.blurry, px)
    np.testing.assert_array_equal(s.frames.exposure_us, exposures)
    np.testing.assert_array_equal(s.events.view_index, np.searchsorted(ev.t_us, exposures, side="left"))


def test_npz_size_members(tmp_path):
    ev = random_events(100)
    f = tmp_path / "ev.npz"
    np.savez(f, events=np.stack([ev.t_us, ev.x, ev.y, ev.p01], 1), width=np.int64(W), height=np.int64(H))
    out = tmp_path / "s.h5"
    assert run_ingest("numpy", f, out, "--time-unit", "us", "--columns", "t,x,y,p", "--intrinsics", K_OPT) == 0
    s = _check(out, ev)
    assert (s.camera.width, s.camera.height) == (W, H)


@pytest.mark.parametrize(
    "case,expected",
    [
        ("no unit", "carry no time unit; give --time-unit"),
        ("no columns", "say which column is which, e.g. --columns t,x,y,p"),
        ("bad columns", "--columns: expected t, x, y, p each once"),
        ("backwards", "timestamps go backwards at event 7"),
        ("polarity", "polarity of event 3 is 2"),
        ("outside", "x of event 5 is 11, outside the sensor"),
        ("truncated npy", "truncated: "),
        ("truncated npz", "not a readable .npz archive"),
        ("lengths", "event arrays differ in length"),
        ("objects", "holds Python objects"),
        ("not numpy", "neither a .npy array nor an .npz archive"),
        ("missing field", "no field for p"),
    ],
)
def test_errors(tmp_path, capsys, case, expected):
    ev = random_events(50)
    a = np.stack([ev.t_us, ev.x, ev.y, ev.p01], 1)
    f = tmp_path / "ev.npy"
    opts = ["--time-unit", "us", "--columns", "t,x,y,p", "--sensor-size", SIZE, "--intrinsics", K_OPT]
    if case == "no unit":
        np.save(f, a)
        opts = opts[2:]
    elif case == "no columns":
        np.save(f, a)
        opts = opts[:2] + opts[4:]
    elif case == "bad columns":
        np.save(f, a)
        opts[3] = "t,x,x,p"
    elif case == "backwards":
        a[7, 0] = a[6, 0] - 1
        np.save(f, a)
    elif case == "polarity":
        a[3, 3] = 2
        np.save(f, a)
    elif case == "outside":
        a[5, 1] = W
        np.save(f, a)
    elif case == "truncated npy":
        np.save(f, a)
        f.write_bytes(f.read_bytes()[:-20])
    elif case == "truncated npz":
        f = tmp_path / "ev.npz"
        np.savez_compressed(f, t=ev.t_us, x=ev.x, y=ev.y, p=ev.p01)
        f.write_bytes(f.read_bytes()[:-30])
        opts = opts[:2] + opts[4:]
    elif case == "lengths":
        f = tmp_path / "ev.npz"
        np.savez(f, t=ev.t_us, x=ev.x[:-1], y=ev.y, p=ev.p01)
        opts = opts[:2] + opts[4:]
    elif case == "objects":
        np.save(f, np.array([{"t": 1}] * 4, dtype=object), allow_pickle=True)
    elif case == "not numpy":
        f.write_text("t x y p\n")
    elif case == "missing field":
        rec = np.zeros(3, dtype=[("t", "<i8"), ("x", "<u2"), ("y", "<u2")])
        np.save(f, rec)
        opts = opts[:2] + opts[4:]
    err = expect_failure(capsys, "numpy", f, tmp_path / "s.h5", *opts)
    assert expected in err, err
    if not err.startswith("eigs ingest: error: --"):
        assert err.startswith(f"eigs ingest: error: {f}"), err


def test_columns_refused_elsewhere(tmp_path, capsys):
    err = expect_failure(capsys, "txt", tmp_path, tmp_path / "s.h5", "--columns", "t,x,y,p")
    assert "--columns: does not apply to the txt format" in err
