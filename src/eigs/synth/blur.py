"""How a view's blurry frame is made from the sharp renders of its exposure (scene parameter ``blur_synthesis``).

``average`` (the default, unchanged): the mean of all ``subframes + 1`` sub-frames of the exposure, a nearly
continuous exposure (81 renders at the defaults).

``e2nerf``: E²NeRF's blur synthesis as it applies to our renderer. E²NeRF (Qi et al., ICCV 2023, §5.1; code
iCVTEAM/E2NeRF@487fec175c8729fdb49c22a2de1a093ca9192fe9, ``orginal_data&preprocessing/synthetic/Blur-synthesizing/``)
renders 17 sharp images per view with Blender and turns them into one blurry frame by an inverse ISP, a mean in
the raw domain, a clamp and the ISP again. Each of its steps, and what we take of it:

- **17 renders, first at the exposure start, last at its end** (k·T/16, k = 0..16). The paper: "17 sharp images
  per viewpoint" (§5.1; ../shared/docs/e2nerf-dataset.md §1). Its loader reads the latent poses as entries 1, 5,
  9, 13, 17 of each view's ``transform_matrix`` list (``load_blender.py`` l.55), its event bins end at entry 17
  (``event-preprocessing.py``: edges 0.05, 0.09, 0.13, 0.17 s at 10 ms per entry; e2nerf-dataset.md §2, §5), and
  the test pose is entry 1 (``load_blender.py`` l.64), so entries 1..17 are the exposure from its first latent
  pose to its last, 16 steps. Our latent times are start + k·T/B (:meth:`Timeline.latent_times`), so with B = 4
  they are renders 1, 5, 9, 13, 17 of the 17, as in E²NeRF. (The README's example passes ``--scale_factor 18``;
  we follow the paper's 17, which the latent-pose indices also imply; entry 0 would lie T/16 before the exposure.)
- **A mean, not a sum, in the raw domain**: ``main.py`` l.70 sums the unprocessed frames, but ``unprocess``
  divides each by ``iso · scale_factor · input_exposure`` (``unprocess.py`` l.61, l.69) and ``process`` multiplies
  the sum by ``output_exposure · output_iso`` = ``input_exposure · input_iso`` (``main.py`` l.62, ``process.py``
  l.205, l.208): the factors cancel to the mean of the ``scale_factor`` raw frames.
- **Inverse ISP, then ISP**: E²NeRF's inverse ISP undoes Blender's display encoding (its tone curve
  3x² − 2x³ and gamma 2.2, ``unprocess.py`` l.6, l.13) to get linear raw values, and its ISP re-applies them
  (``process.py`` l.8, l.15). Our renderer already renders linear radiance (docs/synthetic.md, "Intensity
  domain"), so the inverse ISP is the identity on our renders, and the display transform applied after the mean
  is the scene's own ``camera_response`` (``linear`` or ``srgb``), the one the sharp ground truth and every
  stage's decoder use — as in E²NeRF the blurry frame and the sharp ground truth share one display encoding.
- **Clamp the raw mean to [0, 1]** (``main.py`` l.75): applied (a no-op here, each render being in [0, 1]).
- **Colour correction matrix**: ``util.random_ccm`` draws a random CCM, then overwrites it with the identity
  (``util.py`` l.104–105): nothing to apply.
- **White balance**: ``util.random_gains`` returns fixed gains (red 2.15, blue 1.7; the random draws are
  commented out, ``util.py`` l.113–116), divided out before the mean and multiplied back after it; they cancel
  except for a highlight blend above 0.9 in ``inv_white_balance`` (``unprocess.py`` l.46–56). Our renderer has
  no white-balance stage (it renders the camera's RGB): not applied.
- **Bayer mosaic and bilinear demosaic** (``unprocess.mosaic``, ``process.demosaic``): not applied; our renderer
  has no colour filter array (docs/synthetic.md: not modelled).
- **Shot and read noise** added in ``process`` (``process.py`` l.206, l.209): not applied; frame noise is the
  separate parameter ``frame_noise``, so the blur sampling can be compared alone. (Running E²NeRF's released
  code on flat images gives 1–2 DN of noise per channel; docs/synthetic.md, "Blur synthesis".)
- **8-bit output**: E²NeRF truncates (``util.image_real_to_8bit``, ×255 then ``uint8``); we keep the scene's
  rounding, shared with the sharp ground truth (truncation would put the blurry frames 0.5 DN below it).
"""

from __future__ import annotations

import numpy as np

BLUR_SYNTHESIS_CHOICES: tuple[str, ...] = ("average", "e2nerf")
E2NERF_RENDERS = 17  # sharp renders per view (E²NeRF paper §5.1)


def e2nerf_subframe_indices(subframes: int) -> np.ndarray:
    """(17,) int64 indices into an exposure's ``subframes + 1`` sub-frames (at start + i·T/subframes) of E²NeRF's
    17 renders at start + k·T/16, k = 0..16. ``subframes`` must be a multiple of 16 (checked by
    :func:`eigs.synth.scenes.check_params`)."""
    steps = E2NERF_RENDERS - 1
    if subframes % steps:
        raise ValueError(f"subframes ({subframes}) must be a multiple of {steps} for E²NeRF's 17 renders")
    return (subframes // steps) * np.arange(E2NERF_RENDERS, dtype=np.int64)


def exposure_mean(frames: np.ndarray, blur_synthesis: str) -> np.ndarray:
    """The blurry frame of one exposure in linear intensity, before frame noise and the display transform.

    ``frames``: (S + 1, H, W, C) float32 linear sharp sub-frames at start + i·T/S, i = 0..S (both ends).
    ``average``: the mean of all S + 1; ``e2nerf``: the mean of the 17 at k·T/16 (:func:`e2nerf_subframe_indices`),
    clamped to [0, 1]. Returns (H, W, C) float64, accumulated in float64 (a static exposure gives its sharp frame
    bit for bit).
    """
    if blur_synthesis == "average":
        return frames.astype(np.float64).sum(axis=0) / frames.shape[0]
    if blur_synthesis == "e2nerf":
        picked = frames[e2nerf_subframe_indices(frames.shape[0] - 1)]
        return np.clip(picked.astype(np.float64).sum(axis=0) / picked.shape[0], 0.0, 1.0)
    raise ValueError(f"blur_synthesis must be one of {BLUR_SYNTHESIS_CHOICES}, got {blur_synthesis!r}")
