"""APS frame noise of the real DAVIS346 recording beside the davis346 frame-noise model (docs/synthetic.md, "Frame
noise"): ``.venv/bin/python bench/aps_noise.py [AEDAT4]`` prints JSON (default: ../shared/data/real/davis346_lab).

The recording is read through eigs.ingest.aedat4 (frames, exposures, events); eigs.synth.frame_noise_stats measures it;
the model's temporal noise is predicted at the recording's mean level (shot + read + 8-bit quantisation)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

DEFAULT = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "real" / "davis346_lab" / "davis.aedat4"


def read_davis(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Frames ``(V, H, W)`` uint8, exposures ``(V, 2)`` µs and the events' x, y, t of an AEDAT 4 file."""
    from eigs.ingest.aedat4 import open_aedat4_source
    from eigs.ingest.options import IngestOptions

    src = open_aedat4_source(str(path), IngestOptions())
    assert src.load_frames is not None and src.events is not None and src.exposure_us is not None
    frames = src.load_frames(np.arange(src.n_frames))[..., 0]
    chunks = list(src.events(src.width, src.height))
    x, y, t = (np.concatenate([c[i] for c in chunks]) for i in range(3))
    return frames, src.exposure_us, x, y, t


def report(path: Path) -> dict:
    from eigs.synth.frame_noise import DN, MODELS
    from eigs.synth.frame_noise_stats import QUANTISATION_VAR, measure

    got = measure(*read_davis(path))
    model = MODELS["davis346"]
    level = got["mean_level_dn"] * DN
    predicted = float(np.sqrt(model.temporal_variance(level) / DN**2 + QUANTISATION_VAR))
    configured = {"read_noise_dn": model.read_noise_fs / DN, "column_fpn_dn": model.column_fpn_fs / DN,
                  "pixel_fpn_dn": model.pixel_fpn_fs / DN, "full_well_e": model.full_well_e,
                  "gain_e_per_dn": model.full_well_e / 255, "temporal_std_dn_at_mean_level": predicted}  # fmt: skip
    return {"recording": str(path), "measured": got, "configured": configured}


if __name__ == "__main__":
    print(json.dumps(report(Path(sys.argv[1]) if len(sys.argv) > 1 else DEFAULT.resolve()), indent=2))
