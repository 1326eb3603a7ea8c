"""`eigs edi` end to end on a small simulated scene file: artifact, PNG names, errors; `--no-events`."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest

from eigs.artifacts.edi import latent_png_name, parse_latent_png_name, read_edi
from eigs.cli import main
from eigs.scene import BinnedEvents, write_scene
from tests.edi.sim import make_scene


def test_cli_end_to_end(tmp_path, capsys):
    scene, _ = make_scene(n_views=2, h=32, w=40, seed=1)
    sp = tmp_path / "scene.h5"
    write_scene(scene, sp)
    out = tmp_path / "b2" / "edi.h5"
    lat = tmp_path / "b2" / "latent"
    assert main(["edi", str(sp), "-o", str(out), "--latent-dir", str(lat), "--bins", "2", "--threads", "1"]) == 0
    res = read_edi(out)
    assert res.mode == "estimated" and res.n_bins == 2 and res.latent.shape == (2, 3, 32, 40, 3)
    assert res.event_mask is not None and res.event_mask.shape == (32, 40)
    names = sorted(p.name for p in lat.iterdir())
    assert names == sorted(latent_png_name(v, k) for v in range(2) for k in range(3))
    assert parse_latent_png_name(names[-1]) == (1, 2)
    # cum_counts between latent times are the binned events
    ev = scene.events
    a, b = ev.view_index[1]
    sel = (ev.t[a:b] >= res.timestamps_us[1, 0]) & (ev.t[a:b] < res.timestamps_us[1, 2])
    np.testing.assert_array_equal(
        res.cum_counts[1, 2].sum(), ev.p[a:b][sel].astype(np.int64).sum()
    )
    # bad input → one-line error, exit 2
    assert main(["edi", str(sp), "-o", str(out), "--bins", "0"]) == 2
    assert "--bins" in capsys.readouterr().err
    assert main(["edi", str(tmp_path / "missing.h5"), "-o", str(out)]) == 2


def _prebinned(scene, bins: int = 2):
    """The same frames with E²NeRF-style pre-binned events instead of raw events (source names E²NeRF)."""
    from eigs.edi.binning import bin_events, latent_times

    ev = scene.events
    edges = latent_times(scene.frames.exposure_us, bins)
    h, w = scene.frames.blurry.shape[1:3]
    counts = np.stack([
        bin_events(ev.x[a:b], ev.y[a:b], ev.t[a:b], ev.p[a:b], edges[v], h, w, None).astype(np.int32)
        for v, (a, b) in enumerate(ev.view_index)
    ])  # fmt: skip
    return replace(scene, events=None, binned=BinnedEvents(counts, edges), source="e2nerf-synthetic:/toy")


def _edi_outputs(out, lat) -> tuple[dict, dict]:
    """Every dataset and attribute of an edi.h5 and the bytes of each latent PNG."""
    import h5py

    with h5py.File(out, "r") as f:
        data = {k: f[k][()] for k in f} | {f"@{k}": f.attrs[k] for k in f.attrs}
    return data, {p.name: p.read_bytes() for p in sorted(lat.iterdir())}


@pytest.mark.parametrize("kind", ["raw", "prebinned"])
def test_no_events_passes_the_frames_through(tmp_path, monkeypatch, kind):
    """`eigs edi --no-events` (the edi_frames job of an `events: false` scene) on a scene with events: every latent
    frame is its view's blurry frame, every view sharp, no event counted; the result equals the existing no-events
    path (`eigs edi` on the same scene written without its events) file for file; the events are not read (the
    scene's event arrays are damaged, binning and the threshold search raise if called)."""
    import h5py

    from eigs.edi import binning
    from eigs.edi import threshold as thr
    from eigs.edi.pipeline import without_events

    scene, _ = make_scene(n_views=2, h=24, w=32, seed=2)
    scene = scene if kind == "raw" else _prebinned(scene)
    with_events, without = tmp_path / "scene.h5", tmp_path / "frames_only.h5"
    write_scene(scene, with_events)
    write_scene(without_events(scene), without)
    with h5py.File(with_events, "a") as f:  # unreadable events: reading them would fail validation
        name = "events/x" if kind == "raw" else "events/binned"
        del f[name]
        f[name] = np.zeros(3, np.uint16 if kind == "raw" else np.int32)
    assert main(["edi", str(with_events), "-o", str(tmp_path / "x.h5"), "--bins", "2"]) == 2  # damaged indeed

    ref_out, ref_lat = tmp_path / "ref" / "edi.h5", tmp_path / "ref" / "latent"
    args = ["--bins", "2", "--threads", "1"]
    assert main(["edi", str(without), "-o", str(ref_out), "--latent-dir", str(ref_lat), *args]) == 0

    def refuse(*a, **k):
        raise AssertionError("no binning or threshold search with --no-events")

    for mod, fn in ((binning, "bin_events"), (binning, "cumulative_counts"), (thr, "bounded_search")):
        monkeypatch.setattr(mod, fn, refuse)
    out, lat = tmp_path / "b2" / "edi.h5", tmp_path / "b2" / "latent"
    assert main(["edi", str(with_events), "-o", str(out), "--latent-dir", str(lat), "--no-events", *args]) == 0

    res = read_edi(out)
    blurry = scene.frames.blurry
    assert res.n_bins == 2 and res.sharp.all() and not res.event_count.any() and not res.cum_counts.any()
    assert res.mode == ("estimated" if kind == "raw" else "e2nerf")
    np.testing.assert_array_equal(res.latent, np.broadcast_to((blurry / np.float32(255))[:, None], res.latent.shape))
    for v in range(2):
        for k in range(3):
            png = cv2.cvtColor(cv2.imread(str(lat / latent_png_name(v, k))), cv2.COLOR_BGR2RGB)
            np.testing.assert_array_equal(png, blurry[v])
    got, ref = _edi_outputs(out, lat), _edi_outputs(ref_out, ref_lat)
    assert got[0].keys() == ref[0].keys() and got[1] == ref[1]
    for key in got[0]:
        np.testing.assert_array_equal(got[0][key], ref[0][key], err_msg=key)


def test_no_events_writes_nothing_on_error(tmp_path):
    """An error leaves neither edi.h5 nor the latent folder: bad options fail before writing, and a latent folder
    that cannot be written takes the just-written edi.h5 with it."""
    scene, _ = make_scene(n_views=2, h=16, w=20, seed=3)
    sp = tmp_path / "scene.h5"
    write_scene(scene, sp)
    out, lat = tmp_path / "b2" / "edi.h5", tmp_path / "b2" / "latent"
    assert main(["edi", str(sp), "-o", str(out), "--latent-dir", str(lat), "--no-events", "--bins", "0"]) == 2
    assert main(["edi", str(tmp_path / "missing.h5"), "-o", str(out), "--latent-dir", str(lat), "--no-events"]) == 2
    blocker = tmp_path / "b2" / "file"
    blocker.parent.mkdir()
    blocker.write_text("not a directory")
    with pytest.raises(OSError):
        main(["edi", str(sp), "-o", str(out), "--latent-dir", str(blocker / "latent"), "--no-events"])
    assert sorted(p.name for p in out.parent.iterdir()) == ["file"]
