"""The held-out scores every trainer logs (eigs.train.loop.held_out_scores): PSNR by kind, and on the novel views the
sharpness ratio and coherence of eigs.metrics.sharpness, checked against known answers: the ground truth itself, a
flat render, a render at half contrast, and a view whose ground truth is flat."""

from __future__ import annotations

import math

import numpy as np
import torch

from eigs.train.data import HeldOut
from eigs.train.loop import HELD_OUT_COLUMNS, held_out_scores


def _held(images: np.ndarray, kind: list[int]) -> HeldOut:
    s = len(images)
    return HeldOut(c2w=torch.eye(4, dtype=torch.float64).repeat(s, 1, 1), K=torch.eye(3).repeat(s, 1, 1),
                   images=torch.from_numpy(images), kind=np.array(kind))


def _textured(seed: int, h: int = 32, w: int = 40) -> np.ndarray:
    """(H, W, 3) float32 on the 8-bit grid, mean 0.5, detail at every frequency."""
    rng = np.random.default_rng(seed)
    return (np.round(rng.uniform(0.25, 0.75, (h, w, 3)) * 255) / 255).astype(np.float32)


def test_the_ground_truth_scores_one_and_blur_views_do_not_count():
    imgs = np.stack([_textured(0), _textured(1), _textured(2)])
    held = _held(imgs, [1, 1, 0])
    flat_blur = {2: torch.full_like(held.images[2], 0.5)}  # a bad blur-view render must not touch the novel scores
    out = held_out_scores(lambda i: flat_blur.get(i, held.images[i]), held)
    assert set(out) == set(HELD_OUT_COLUMNS)
    assert math.isinf(out["psnr_novel"]) or out["psnr_novel"] > 90
    assert out["sharpness_novel"] == 1.0 and out["coherence_novel"] == 1.0
    assert out["psnr_blur"] < 20


def test_flat_and_half_contrast_renders():
    held = _held(np.stack([_textured(3)]), [1])
    gt = held.images[0].double()
    flat = held_out_scores(lambda i: torch.full_like(held.images[0], 0.5), held)
    assert abs(flat["sharpness_novel"]) < 1e-12 and abs(flat["coherence_novel"]) < 1e-12
    half = held_out_scores(lambda i: (0.5 + 0.5 * (gt - 0.5)).float(), held)
    # detail at half amplitude: power ratio 1/4, coherence 1/2, up to the renders' 8-bit rounding
    assert abs(half["sharpness_novel"] - 0.25) < 0.01 and abs(half["coherence_novel"] - 0.5) < 0.01


def test_a_flat_ground_truth_is_left_out_and_none_gives_nan():
    flat_gt = np.full((1, 32, 40, 3), 0.5, np.float32)
    held = _held(np.concatenate([flat_gt, _textured(4)[None]]), [1, 1])
    out = held_out_scores(lambda i: held.images[i], held)
    assert out["sharpness_novel"] == 1.0  # the mean over the one defined view
    only_flat = held_out_scores(lambda i: held.images[i], _held(flat_gt, [1]))
    assert math.isnan(only_flat["sharpness_novel"]) and math.isnan(only_flat["coherence_novel"])
    nothing = held_out_scores(lambda i: held.images[i], None)
    assert all(math.isnan(v) for v in nothing.values())
