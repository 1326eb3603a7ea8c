"""The EDI artifact ``results/<scene>/b{B}/edi.h5`` (version 1): latent sharp frames and event integrals.

Written by the ``edi`` stage, read by SfM, initialization, training (event loss, EDI baseline) and evaluation.
Only this module knows its HDF5 paths. Latent PNGs beside it are named by :func:`latent_png_name`.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from eigs.artifacts._h5 import open_artifact
from eigs.errors import H5_READ_ERRORS, EigsError
from eigs.util.atomic import atomic_path, ensure_space, nbytes_of

FORMAT_NAME = "eigs-edi"
FORMAT_VERSION = 1
MODES = ("e2nerf", "estimated")
_PNG = re.compile(r"^v(\d{4})_k(\d{2})\.png$")


def latent_png_name(view: int, k: int) -> str:
    """File name of latent frame ``k`` of training view ``view`` (e.g. ``v0007_k03.png``)."""
    return f"v{view:04d}_k{k:02d}.png"


def write_latent_pngs(
    latent: np.ndarray, directory: str | os.PathLike, slots: Iterable[tuple[int, int]] | None = None
) -> int:
    """The one latent-PNG writer: frames ``latent[v, k]`` ((V, L, H, W, C) float in [0, 1]) as 8-bit PNGs named
    :func:`latent_png_name` in ``directory``, created atomically (replacing it). ``slots``: the (v, k) to write
    (default: all). Rounding: :func:`eigs.util.image.to_uint8`. Returns the number of files."""
    from eigs.util.image import write_png

    if slots is None:
        slots = [(v, k) for v in range(latent.shape[0]) for k in range(latent.shape[1])]
    n = 0
    with atomic_path(directory, directory=True) as tmp:
        for v, k in slots:
            write_png(Path(tmp) / latent_png_name(v, k), latent[v, k])
            n += 1
    return n


def parse_latent_png_name(name: str) -> tuple[int, int]:
    """Inverse of :func:`latent_png_name`: ``"v0007_k03.png"`` → ``(7, 3)``."""
    m = _PNG.match(os.path.basename(name))
    if m is None:
        raise EigsError(name, "not a latent frame name (expected vVVVV_kKK.png)")
    return int(m.group(1)), int(m.group(2))


@dataclass
class EdiResult:
    """EDI output for V views and B bins (L = B + 1 latent times per view).

    - ``latent``: (V, L, H, W, C) float32 in [0, 1], the latent sharp frames in the scene's pixel domain
      (same camera response as the blurry frames).
    - ``timestamps_us``: (V, L) int64 latent times.
    - ``cum_counts``: (V, L, H, W) int32 signed event counts from latent time 0 to latent time k (k = 0 is all
      zero); the event integral between latent times a and b is ``cum_counts[:, b] - cum_counts[:, a]``.
    - ``threshold``: (V,) float64 contrast threshold used per view (log-intensity units per event; in
      ``e2nerf`` mode the constant c = 0.3 applied to 0–255 values).
    - ``sharp``: (V,) bool, views with too few events: their latent frames are copies of the blurry frame and
      later stages may render them once.
    - ``event_count``: (V,) int64 events inside each exposure; ``events_per_pixel``: (V,) float64;
      ``blur_extent_px``: (V,) float64 estimated blur extent.
    - ``mode``: ``e2nerf`` or ``estimated``; ``threshold_scope``: ``scene``, ``view`` or ``given``.
    - ``event_mask``: optional (H, W) bool, pixels whose events were ignored (hot pixels, flicker); their
      ``cum_counts`` are zero, so an event loss should skip them. None when no mask was applied.
    - ``threshold_pos_map``, ``threshold_neg_map``: optional (H, W) float64 per-pixel ON/OFF contrast thresholds
      (estimated mode with per-pixel calibration, ``docs/edi.md``); the latent frames were computed with them
      (ON events count c⁺, OFF events c⁻ at each pixel) instead of ``threshold``. None (absent) otherwise;
      files written before they existed read as None.
    """

    latent: np.ndarray
    timestamps_us: np.ndarray
    cum_counts: np.ndarray
    threshold: np.ndarray
    sharp: np.ndarray
    event_count: np.ndarray
    events_per_pixel: np.ndarray
    blur_extent_px: np.ndarray
    mode: str
    threshold_scope: str
    scene_name: str = ""
    event_mask: np.ndarray | None = None
    threshold_pos_map: np.ndarray | None = None
    threshold_neg_map: np.ndarray | None = None

    @property
    def n_views(self) -> int:
        return int(self.latent.shape[0])

    @property
    def n_bins(self) -> int:
        return int(self.latent.shape[1]) - 1

    def validate(self, path: str | os.PathLike) -> None:
        """Shapes, dtypes and finiteness; raises :class:`EigsError` naming ``path``."""
        v, l_ = self.latent.shape[:2]
        checks = [
            (
                self.latent.ndim == 5 and self.latent.dtype == np.float32,
                "latent must be (V, L, H, W, C) float32",
            ),
            (
                self.timestamps_us.shape == (v, l_) and self.timestamps_us.dtype == np.int64,
                "timestamps_us must be (V, L) int64",
            ),
            (
                self.cum_counts.shape == (v, l_, *self.latent.shape[2:4])
                and self.cum_counts.dtype == np.int32,
                "cum_counts must be (V, L, H, W) int32",
            ),
            (self.threshold.shape == (v,), "threshold must be (V,)"),
            (self.sharp.shape == (v,) and self.sharp.dtype == np.bool_, "sharp must be (V,) bool"),
            (self.event_count.shape == (v,), "event_count must be (V,)"),
            (self.events_per_pixel.shape == (v,), "events_per_pixel must be (V,)"),
            (self.blur_extent_px.shape == (v,), "blur_extent_px must be (V,)"),
            (self.mode in MODES, f"mode must be one of {MODES}"),
            (l_ >= 2, "at least 2 latent times (1 bin) per view"),
            (
                self.event_mask is None
                or (self.event_mask.dtype == np.bool_ and self.event_mask.ndim == 2),
                "event_mask must be (H, W) bool",
            ),
            (
                (self.threshold_pos_map is None) == (self.threshold_neg_map is None),
                "threshold_pos_map and threshold_neg_map come together",
            ),
            (
                self.threshold_pos_map is None
                or (
                    self.threshold_pos_map.ndim == 2
                    and self.threshold_neg_map is not None
                    and self.threshold_neg_map.shape == self.threshold_pos_map.shape
                ),
                "threshold_pos_map / threshold_neg_map must be (H, W)",
            ),
        ]
        for ok, msg in checks:
            if not ok:
                raise EigsError(path, msg)
        for name in ("latent", "threshold", "events_per_pixel", "blur_extent_px"):
            a = getattr(self, name)
            if not np.all(np.isfinite(a)):
                raise EigsError(path, f"{name} has NaN/Inf values")
        for name in ("threshold_pos_map", "threshold_neg_map"):
            a = getattr(self, name)
            if a is not None and not (np.all(np.isfinite(a)) and np.all(a > 0)):
                raise EigsError(path, f"{name} must be finite and positive")
        if self.latent.size and (self.latent.min() < 0 or self.latent.max() > 1):
            raise EigsError(path, "latent must lie in [0, 1]")
        if v and np.any(self.cum_counts[:, 0] != 0):
            raise EigsError(path, "cum_counts[:, 0] must be zero")


def write_edi(result: EdiResult, path: str | os.PathLike) -> None:
    """Validate and write atomically."""
    result.validate(path)
    ensure_space(path, nbytes_of(result))
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        f.attrs.update(
            format=FORMAT_NAME,
            version=FORMAT_VERSION,
            mode=result.mode,
            bins=result.n_bins,
            threshold_scope=result.threshold_scope,
            scene=result.scene_name,
        )
        chunks = (1, 1, *result.latent.shape[2:]) if result.n_views else None
        f.create_dataset("latent", data=result.latent, chunks=chunks)
        for name in (
            "timestamps_us",
            "cum_counts",
            "threshold",
            "sharp",
            "event_count",
            "events_per_pixel",
            "blur_extent_px",
        ):
            f.create_dataset(name, data=getattr(result, name))
        if result.event_mask is not None:
            f.create_dataset("event_mask", data=result.event_mask)
        if result.threshold_pos_map is not None and result.threshold_neg_map is not None:
            f.create_dataset("threshold_pos_map", data=np.asarray(result.threshold_pos_map, np.float64))
            f.create_dataset("threshold_neg_map", data=np.asarray(result.threshold_neg_map, np.float64))


def read_edi(path: str | os.PathLike, *, latent: bool = True) -> EdiResult:
    """Read and validate. ``latent=False`` skips the large arrays: ``latent`` comes back as (V, L, 0, 0, C)
    and ``cum_counts`` as (V, L, 0, 0), everything else in full."""
    p = Path(path)
    try:
        with open_artifact(p, FORMAT_NAME, FORMAT_VERSION, "EDI", "edi") as f:
            lat = (
                f["latent"][()]
                if latent
                else np.zeros((*f["latent"].shape[:2], 0, 0, f["latent"].shape[4]), np.float32)
            )
            res = EdiResult(
                latent=lat,
                timestamps_us=f["timestamps_us"][()],
                cum_counts=f["cum_counts"][()]
                if latent
                else np.zeros((*f["latent"].shape[:2], 0, 0), np.int32),
                threshold=f["threshold"][()],
                sharp=f["sharp"][()],
                event_count=f["event_count"][()],
                events_per_pixel=f["events_per_pixel"][()],
                blur_extent_px=f["blur_extent_px"][()],
                mode=str(f.attrs["mode"]),
                threshold_scope=str(f.attrs["threshold_scope"]),
                scene_name=str(f.attrs.get("scene", "")),
                event_mask=f["event_mask"][()] if "event_mask" in f else None,
                threshold_pos_map=f["threshold_pos_map"][()] if "threshold_pos_map" in f else None,
                threshold_neg_map=f["threshold_neg_map"][()] if "threshold_neg_map" in f else None,
            )
    except H5_READ_ERRORS as err:
        raise EigsError(p, f"corrupted EDI file ({err})") from None
    res.validate(p)
    return res
