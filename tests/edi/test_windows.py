"""EDI reads the raw events a view's window at a time (eigs.edi.pipeline, "Memory"): a scene file's
:class:`eigs.scene.EventFile`, read in small chunks, gives the result of the events in memory exactly; no read is
larger than a view or a chunk; the per-pixel calibration fits the gaps whose integrals fit its memory budget."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from eigs.edi import pipeline
from eigs.edi.pipeline import EdiOptions, compute_edi
from eigs.scene import EventFile, Events, read_scene, write_scene
from tests.edi.sim import make_scene

H, W = 48, 64
TRUTH: dict[str, tuple[np.ndarray, np.ndarray]] = {}


@pytest.fixture(scope="module")
def mismatch():
    rng = np.random.default_rng(1)
    maps = tuple(np.maximum(rng.normal(0.2, 0.03, (H, W)), 0.05) for _ in range(2))
    scene, _ = make_scene(n_views=12, h=H, w=W, c=0.2, shake_px=6.0, seed=3, c_maps=maps)
    TRUTH["maps"] = maps  # (c⁺, c⁻) the events were simulated with
    return scene


FIELDS = ("latent", "timestamps_us", "cum_counts", "threshold", "sharp", "event_count", "blur_extent_px",
          "event_mask", "threshold_pos_map", "threshold_neg_map")


class Spy:
    """An :class:`eigs.scene.EventSource` over events in memory that records the size of every read."""

    def __init__(self, ev: Events, rows: int):
        self.ev, self.rows, self.reads = ev, rows, []
        self.view_index = ev.view_index

    def __len__(self) -> int:
        return len(self.ev)

    def window(self, start: int, stop: int) -> Events:
        self.reads.append(stop - start)
        return self.ev.window(start, stop)

    def chunks(self, rows: int | None = None):
        for c in self.ev.chunks(self.rows):
            self.reads.append(len(c))
            yield c


@pytest.mark.parametrize("opts", [EdiOptions(show_progress=False),
                                  EdiOptions(show_progress=False, per_pixel_threshold=False),
                                  EdiOptions(show_progress=False, threshold_scope="view", mask_top=0.02,
                                             mask_factor=1.5)],
                         ids=["per-pixel", "global", "per-view+mask"])
def test_scene_file_read_by_windows_gives_the_result_in_memory(mismatch, tmp_path, monkeypatch, opts):
    path = tmp_path / "scene.h5"
    write_scene(mismatch, path)
    ref = compute_edi(mismatch, opts)
    monkeypatch.setattr(EventFile, "READ_ROWS", 997)  # many chunks, none aligned with a view
    got = compute_edi(read_scene(path, events=False), opts, source=EventFile(path))
    assert got.mode == ref.mode == "estimated"
    for name in FIELDS:
        a, b = getattr(got, name), getattr(ref, name)
        assert (a is None and b is None) or np.array_equal(a, b), name


def test_no_read_is_larger_than_a_view_or_a_chunk(mismatch):
    vi = mismatch.events.view_index
    largest_view = int((vi[:, 1] - vi[:, 0]).max())
    rows = 500
    spy = Spy(mismatch.events, rows)
    compute_edi(mismatch, EdiOptions(show_progress=False), source=spy)
    assert len(mismatch.events) > 12 * largest_view // 2 and largest_view > rows
    assert spy.reads and max(spy.reads) == largest_view  # each view's window, whole chunks of the rest


def test_a_view_index_is_not_needed(mismatch):
    """Without a view index the windows come from the exposures, counted chunk by chunk."""
    ev = mismatch.events
    bare = Events(ev.x, ev.y, ev.t, ev.p, None)
    got = compute_edi(mismatch, EdiOptions(show_progress=False), source=Spy(bare, 777))
    ref = compute_edi(mismatch, EdiOptions(show_progress=False))
    assert np.array_equal(got.latent, ref.latent)


def test_calibration_gaps_fit_the_budget(monkeypatch):
    counts = np.full(9, 10_000, np.int64)  # 9 views: 8 gaps, each view's integrals 24·(2n) + 24·n bytes
    per_view = 24 * 2 * 10_000 + 24 * 10_000
    gaps = np.ones(8, bool)
    gaps[5] = False
    monkeypatch.setattr(pipeline, "INTEGRAL_BUDGET_BYTES", 9 * per_view)
    assert np.array_equal(pipeline._calibration_gaps(gaps, counts, 100_000), gaps)  # all fit
    monkeypatch.setattr(pipeline, "INTEGRAL_BUDGET_BYTES", 6 * per_view)
    sel = pipeline._calibration_gaps(gaps, counts, 100_000)
    views = np.unique(np.concatenate([np.flatnonzero(sel), np.flatnonzero(sel) + 1]))
    assert views.size <= 6 and not sel[5] and np.all(sel <= gaps)
    assert sel.sum() == 3  # 4 gaps need ≥ 7 views here (at most one pair shares a view), 3 evenly spaced need 6
    monkeypatch.setattr(pipeline, "INTEGRAL_BUDGET_BYTES", per_view)
    assert not pipeline._calibration_gaps(gaps, counts, 100_000).any()


def test_over_budget_fits_fewer_gaps_and_says_so(mismatch, monkeypatch, caplog):
    vi = mismatch.events.view_index
    n = (vi[:, 1] - vi[:, 0]).astype(np.int64)
    per_view = 24 * (n + np.minimum(n, H * W)) + 24 * np.minimum(n, H * W)
    budget = int(0.75 * per_view.sum())
    monkeypatch.setattr(pipeline, "INTEGRAL_BUDGET_BYTES", budget)
    built: list[int] = []
    original = pipeline.cal.PolarityIntegral.__init__

    def spy(self, x, *a, **k):
        built.append(len(x))
        original(self, x, *a, **k)

    monkeypatch.setattr(pipeline.cal.PolarityIntegral, "__init__", spy)
    with caplog.at_level(logging.INFO, logger="eigs.edi.pipeline"):
        part = compute_edi(mismatch, EdiOptions(show_progress=False))
    monkeypatch.undo()
    full = compute_edi(mismatch, EdiOptions(show_progress=False))
    assert "per-pixel calibration: 4 of 11 gaps" in caplog.text
    assert len(built) == 12  # the 8 views of the 4 gaps for the calibration, the other 4 for their latent frames
    assert part.threshold_pos_map is not None and np.all(np.isfinite(part.threshold_pos_map))
    assert np.all(np.isfinite(part.latent))
    # fewer gaps estimate less well, but better than one global threshold (σ = 0.03 around 0.2)
    ev = mismatch.events
    q = ev.y.astype(np.int64) * W + ev.x
    for est_part, est_full, true, sign in ((part.threshold_pos_map, full.threshold_pos_map, TRUTH["maps"][0], 1),
                                          (part.threshold_neg_map, full.threshold_neg_map, TRUTH["maps"][1], -1)):
        sel = np.bincount(q[ev.p == sign], minlength=H * W).reshape(H, W) >= 20
        err_full = np.median(np.abs(est_full - true)[sel])
        err_part = np.median(np.abs(est_part - true)[sel])
        err_global = np.median(np.abs(full.threshold[0] - true)[sel])
        assert err_full <= err_part < err_global, (err_full, err_part, err_global)


def test_a_damaged_scene_file_is_named_not_read(mismatch, tmp_path):
    """The checks read_scene makes, made by parts: the view index on opening, each window as it is read."""
    import h5py

    from eigs.errors import EigsError

    path = tmp_path / "s.h5"
    write_scene(mismatch, path)
    with h5py.File(path, "a") as f:
        f["events/view_index"][3, 0] += 1
    with pytest.raises(EigsError, match="view 3's exposure") as err:
        EventFile(path)
    assert str(path) in str(err.value)
    write_scene(mismatch, path)
    k = int(mismatch.events.view_index[5, 0]) + 7
    with h5py.File(path, "a") as f:
        f["events/x"][k] = W + 5
    events = EventFile(path)
    with pytest.raises(EigsError, match=f"outside the {W}×{H} sensor"):
        list(events.chunks(100))
    with pytest.raises(EigsError, match=f"outside the {W}×{H} sensor"):
        compute_edi(read_scene(path, events=False), EdiOptions(show_progress=False), source=events)
