"""APS frame noise of a DAVIS346: photon shot noise, read noise and fixed-pattern noise on the blurry frames.

Scene parameter ``frame_noise`` (``none`` by default, also under the ``davis346`` preset, so every existing config and
its ledger reproduce byte for byte; ``davis346`` turns it on). Units: a frame value is linear intensity as a fraction
of the ADC's full scale (1.0 = the 8-bit 255 the scene stores; 1 DN below = 1/255 of it). For one exposure, every
pixel (row i, column j) and channel c (each colour channel is treated as its own photosite):

    electrons  e    ~ Poisson(x · full_well_e · max(1 + g[i, j, c], 0))     photon shot noise (temporal)
    output     y    = e / full_well_e + n + o[i, j, c] + k[j]
    n ~ N(0, read_noise_fs²) per frame (temporal read noise), o ~ N(0, pixel_fpn_fs²) per pixel (offset FPN),
    k ~ N(0, column_fpn_fs²) per column, shared by its channels (column readout), g ~ N(0, prnu²) (gain FPN)

with ``x`` the exposure's mean linear intensity (the clean blurry frame, already dimmed by ``light_level``, so the
shot noise is that of the scene's light). ``o``, ``k`` and ``g`` are one sensor's: drawn once per scene from the scene
seed (:func:`draw_fixed_pattern`), the same for every frame; ``e`` and ``n`` are new in every frame (:func:`expose`).
The generator then clips to [0, 1] and quantises to 8 bits as for noise-free frames (``eigs.synth.response.encode``).
Not modelled: dark current and its shot noise, the colour filter array and demosaicing, column-wise temporal noise,
the 10-bit ADC's own quantisation (the 8-bit one is coarser), non-linearity near full well.

The values of :data:`MODELS` and their sources are in :data:`SOURCES` and docs/synthetic.md ("Frame noise").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

FRAME_NOISE_CHOICES = ("none", "davis346")
DN = 1.0 / 255.0  # one 8-bit step, as a fraction of full scale


@dataclass(frozen=True)
class FrameNoise:
    """A sensor's APS noise. ``full_well_e``: photo-electrons at full scale (the conversion gain is
    ``full_well_e / 255`` e⁻/DN at 8 bits); the others as fractions of full scale (``prnu``: relative gain)."""

    full_well_e: float
    read_noise_fs: float
    column_fpn_fs: float
    pixel_fpn_fs: float
    prnu: float

    def temporal_variance(self, x: np.ndarray | float, gain: np.ndarray | float = 0.0) -> np.ndarray:
        """Variance over frames (fraction of full scale, squared) of a pixel of mean intensity ``x`` and gain error
        ``gain``, before clipping and quantisation: shot ``x (1 + g) / full_well_e`` plus read noise²."""
        return np.asarray(x) * np.maximum(1.0 + np.asarray(gain), 0.0) / self.full_well_e + self.read_noise_fs**2


# Brandli et al. 2014 (JSSC 49(10), the DAVIS240, whose DAVIS pixel has the DAVIS346's 18.5 µm pitch; [assumed]
# representative of it): APS dynamic range 51 dB and 0.5 % FPN. Dynamic range = full scale / rms read noise.
_DR_DB = 51.0
_FPN_TOTAL = 0.005
_COLUMN_SHARE = 0.5  # [assumed] half the FPN's standard deviation in the column offsets (no published split)
MODELS: dict[str, FrameNoise] = {
    "davis346": FrameNoise(
        full_well_e=41_000.0,
        read_noise_fs=10.0 ** (-_DR_DB / 20.0),
        column_fpn_fs=_COLUMN_SHARE * _FPN_TOTAL,
        pixel_fpn_fs=float(np.sqrt(1.0 - _COLUMN_SHARE**2) * _FPN_TOTAL),
        prnu=0.01,
    ),
}
_BRANDLI = (
    'C. Brandli, R. Berner, M. Yang, S.-C. Liu, T. Delbruck, "A 240 × 180 130 dB 3 µs Latency Global Shutter '
    'Spatiotemporal Vision Sensor", IEEE JSSC 49(10):2333-2341, 2014, doi:10.1109/JSSC.2014.2342715'
)
SOURCES: dict[str, dict[str, str]] = {
    "davis346": {
        "full_well_e": "measured here, no published DAVIS346 full well or conversion gain found: photon transfer on "
                       "../shared/data/real/davis346_lab (a DAVIS346, 8-bit frames, bench/aps_noise.py): the temporal "
                       "variance rises 0.0062 ± 0.0010 DN² per DN (weighted fit over 10 level bins, 17-104 DN), i.e. "
                       "160 e⁻/DN and 41,000 e⁻ at full scale (±2 SE: 31,000-60,000)",
        "read_noise_fs": f"{_BRANDLI}: APS dynamic range 51 dB = full scale / rms read noise → 0.282 % of full scale "
                         "(0.72 DN at 8 bits, ≈ 115 e⁻ at the full well above); the DAVIS346 recording's "
                         "photon-transfer intercept gives 0.68 DN",
        "column_fpn_fs": f"{_BRANDLI}: APS FPN 0.5 % (of full scale); [assumed] half its standard deviation per column "
                         "(0.25 %, 0.64 DN)",
        "pixel_fpn_fs": "the rest of that 0.5 %: sqrt(0.5² − 0.25²) = 0.433 % of full scale (1.10 DN) per pixel",
        "prnu": "[assumed] 1 % photo-response non-uniformity, a typical CMOS figure (none published for the DAVIS); "
                "0.15 DN at the preset's 15-DN frames",
    },
}


@dataclass(frozen=True)
class FixedPattern:
    """One sensor's fixed pattern: ``column`` ``(W,)``, ``pixel`` and ``gain`` ``(H, W, C)`` (fractions of full
    scale; ``gain`` relative)."""

    column: np.ndarray
    pixel: np.ndarray
    gain: np.ndarray


def draw_fixed_pattern(model: FrameNoise, height: int, width: int, channels: int,
                       rng: np.random.Generator) -> FixedPattern:  # fmt: skip
    """The sensor's fixed pattern, drawn once (per scene) from ``rng``: column, then pixel offsets, then gains."""
    column = rng.normal(0.0, model.column_fpn_fs, width)
    pixel = rng.normal(0.0, model.pixel_fpn_fs, (height, width, channels))
    gain = rng.normal(0.0, model.prnu, (height, width, channels))
    return FixedPattern(column, pixel, gain)


def expose(x: np.ndarray, model: FrameNoise, pattern: FixedPattern, rng: np.random.Generator) -> np.ndarray:
    """One noisy exposure of the clean mean linear intensity ``x`` ``(H, W, C)`` in [0, 1]: float64 ``(H, W, C)``,
    not clipped (the module docstring's ``y``). Draws the shot noise, then the read noise, from ``rng``."""
    x = np.asarray(x, dtype=np.float64)
    mean_e = np.clip(x, 0.0, None) * model.full_well_e * np.maximum(1.0 + pattern.gain, 0.0)
    electrons = rng.poisson(mean_e).astype(np.float64)
    read = rng.normal(0.0, model.read_noise_fs, x.shape)
    return electrons / model.full_well_e + read + pattern.pixel + pattern.column[None, :, None]
