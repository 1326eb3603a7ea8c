"""Real data (../shared/data/real/davis346_lab, DAVIS346, nearly static camera under flickering lamps): predict each
APS frame from the previous one by integrating the events between them, with the estimated threshold and the
hot-pixel/flicker mask, and compare with copying the previous frame (issue 6 acceptance).

The scene comes from the ingestion stage (``eigs ingest --format aedat4 --keep-events all``; the recording has no
calibration, so a nominal ``--intrinsics`` is given — EDI does not use it). The prediction is the EDI model carried
across frames: with M_v(c) the exposure average of exp(c·E(t)) of frame v (reference = its exposure start) and N the
signed events from the start of exposure v to the start of exposure v+1,
    Y_{v+1} + ε ≈ (Y_v + ε) · exp(−log M_v(c) + c·N + log M_{v+1}(c)).
"""

from __future__ import annotations

import numpy as np
import pytest

from eigs.cli import main
from eigs.edi.binning import bin_events
from eigs.edi.edi import LOG_EPS, ExposureIntegral, to_linear
from eigs.edi.pipeline import EdiOptions, compute_edi
from eigs.scene import read_scene

pytestmark = pytest.mark.shared


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    return float(10 * np.log10(1.0 / np.mean((a - b) ** 2)))


def predict(scene, v: int, c: float, hot: np.ndarray | None) -> np.ndarray:
    ev, exp = scene.events, scene.frames.exposure_us
    h, w = scene.camera.height, scene.camera.width
    a = to_linear(scene.frames.blurry[v], scene.camera_response)[..., 0]
    ia = ExposureIntegral(ev.x, ev.y, ev.t, ev.p, exp[v, 0], exp[v, 1], exp[v, 0], h, w, hot)
    ib = ExposureIntegral(ev.x, ev.y, ev.t, ev.p, exp[v + 1, 0], exp[v + 1, 1], exp[v + 1, 0], h, w, hot)
    gap = bin_events(ev.x, ev.y, ev.t, ev.p, exp[v : v + 2, 0], h, w, hot)[0]
    log_f = np.clip(-ia.log_mean_exp(c) + c * gap + ib.log_mean_exp(c), -50, 50)
    return np.clip((a + LOG_EPS) * np.exp(log_f) - LOG_EPS, 0.0, 1.0)


def test_davis346_prediction_beats_copying(shared_real, tmp_path, capsys):
    src = shared_real / "davis346_lab" / "davis.aedat4"
    sp = tmp_path / "davis.h5"
    code = main(
        ["ingest", "--format", "aedat4", str(src), "--keep-events", "all", "--intrinsics", "300,300,173,130",
         "-o", str(sp)]
    )
    assert code == 0, capsys.readouterr().err
    scene = read_scene(sp)
    assert scene.frames.n_views == 3 and len(scene.events) == 117_667
    res = compute_edi(scene, EdiOptions(show_progress=False))
    c, hot = float(res.threshold[0]), res.event_mask
    assert res.mode == "estimated" and hot is not None and 0 < hot.mean() <= 0.011
    rows = []
    for v in range(2):
        truth = to_linear(scene.frames.blurry[v + 1], scene.camera_response)[..., 0]
        copy = _psnr(to_linear(scene.frames.blurry[v], scene.camera_response)[..., 0], truth)
        pred = _psnr(predict(scene, v, c, hot), truth)
        naive = _psnr(predict(scene, v, 0.2, None), truth)
        rows.append((copy, pred, naive))
    print(f"davis346: c = {c:.4f}, masked {int(hot.sum())} px; (copy, predicted, naive c=0.2 unmasked) = {rows}")
    np.testing.assert_allclose([r[0] for r in rows], [33.7, 39.3], atol=0.05)  # the copy figures
    for copy, pred, naive in rows:
        assert pred >= copy
        assert naive < copy  # the noise is real: without mask and estimate the prediction is worse
