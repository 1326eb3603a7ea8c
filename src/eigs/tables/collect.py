"""Read ``metrics.json`` files (``eigs evaluate``) and average each run over its scenes.

A run's synthetic metrics (PSNR / SSIM / LPIPS / sharpness / coherence) are means over the scenes with ground truth,
at the novel views (``novel``; the paper's Table I is most likely a novel-view evaluation) and the blur views
(``blur``); BRISQUE is the mean over the scenes without ground truth (the ``all`` group: training views and orbit),
``brisque_sim`` the same over the simulated recordings through the real-data path whose ground truth was hidden from
training (``hidden_ground_truth``: they count among the scenes with ground truth too); training seconds, test-time FPS
and Gaussians are means over every scene of the run. ``sources`` lists the run folders behind the numbers.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from eigs.errors import EigsError

# aggregated column -> (metrics group, key in that group); groups are those of eigs.evaluate
SYNTHETIC_COLUMNS = {
    "psnr": ("novel", "psnr"),
    "ssim": ("novel", "ssim_3dgs"),
    "lpips": ("novel", "lpips_alex"),
    "sharpness": ("novel", "sharpness"),
    "coherence": ("novel", "coherence"),
    "ssim_skimage": ("novel", "ssim_skimage-gaussian"),
    "ssim_deblurnerf": ("novel", "ssim_deblurnerf"),
    "psnr_blur": ("blur", "psnr"),
    "ssim_blur": ("blur", "ssim_3dgs"),
    "lpips_blur": ("blur", "lpips_alex"),
    "sharpness_blur": ("blur", "sharpness"),
    "coherence_blur": ("blur", "coherence"),
}
REAL_COLUMNS = {"brisque": ("all", "brisque")}
# BRISQUE of the scenes with a hidden ground truth (metrics.json ``hidden_ground_truth``), kept apart from real ones
HIDDEN_COLUMNS = {"brisque_sim": ("all", "brisque")}
RUN_COLUMNS = {"time_s": "train_seconds", "fps": "fps", "n_gaussians": "n_gaussians"}
# the motion within the exposure against the ground truth (metrics.json ``motion``, eigs.metrics.motion): means over
# the scenes where the run models motion and the scene has ground-truth poses
MOTION_COLUMNS = {
    "motion_err": "displacement_relative_error",
    "motion_cos": "displacement_cosine",
    "motion_rot_deg": "rotation_error_deg",
}


@dataclass
class RunSummary:
    """One run averaged over its scenes. ``values``: column → mean (NaN when no scene has it); ``scenes``: the
    scenes averaged; ``sources``: run folders; ``per_scene``: scene → metrics document."""

    run: str
    method: str
    bins: int
    values: dict[str, float] = field(default_factory=dict)
    scenes: list[str] = field(default_factory=list)
    sources: list[str] = field(default_factory=list)
    per_scene: dict[str, dict[str, Any]] = field(default_factory=dict)

    def scene_values(self, col: str) -> dict[str, float]:
        """Scene → this run's value of column ``col`` on that scene (finite values only)."""
        out: dict[str, float] = {}
        for scene, d in self.per_scene.items():
            if col in RUN_COLUMNS:
                v = d.get(RUN_COLUMNS[col])
            else:
                spec = SYNTHETIC_COLUMNS.get(col) or (HIDDEN_COLUMNS if is_hidden(d) else REAL_COLUMNS).get(col)
                v = d["metrics"].get(spec[0], {}).get(spec[1]) if spec else None
            if v is not None and math.isfinite(float(v)):
                out[scene] = float(v)
        return out

    def source_pattern(self) -> str:
        """The run folders as one brace pattern, e.g. ``results/{chair,tree}/b4/eigs`` (exact shell expansion)."""
        return brace_pattern(self.sources)


def is_hidden(doc: dict[str, Any]) -> bool:
    """A recording through the real-data path whose ground truth was hidden from training (``eigs evaluate
    --hidden-ground-truth``)."""
    return bool(doc.get("hidden_ground_truth"))


def brace_pattern(paths: list[str]) -> str:
    """Compress paths that differ in one path component into ``prefix/{a,b}/suffix`` (else join with ``;``)."""
    if not paths:
        return ""
    if len(paths) == 1:
        return paths[0]
    parts = [Path(p).parts for p in paths]
    if len({len(p) for p in parts}) == 1:
        differ = [i for i in range(len(parts[0])) if len({p[i] for p in parts}) > 1]
        if len(differ) == 1:
            i = differ[0]
            names = sorted({p[i] for p in parts})
            return str(Path(*parts[0][:i], "{" + ",".join(names) + "}", *parts[0][i + 1 :]))
    return ";".join(sorted(paths))


def read_metrics(path: str | os.PathLike) -> dict[str, Any]:
    p = Path(path)
    try:
        doc = json.loads(p.read_text())
    except (OSError, ValueError) as err:
        raise EigsError(p, f"cannot read metrics ({err})") from None
    if doc.get("format") != "eigs-metrics":
        raise EigsError(p, "not an eigs metrics.json (format field missing)")
    for key in ("run", "scene", "metrics", "ground_truth", "run_dir"):
        if key not in doc:
            raise EigsError(p, f"metrics.json lacks {key!r}")
    return doc


def _mean(values: list[float | None]) -> float:
    v = [float(x) for x in values if x is not None and math.isfinite(float(x))]
    return float(np.mean(v)) if v else math.nan


def summarise(paths: list[str | os.PathLike]) -> dict[str, RunSummary]:
    """Run name → summary, from metrics.json files (one per run and scene)."""
    runs: dict[str, RunSummary] = {}
    for path in paths:
        doc = read_metrics(path)
        name = doc["run"]
        s = runs.setdefault(name, RunSummary(name, str(doc.get("method")), int(doc.get("bins", 0))))
        if doc["scene"] in s.per_scene:
            raise EigsError(path, f"run {name} has two metrics files for scene {doc['scene']}")
        s.per_scene[doc["scene"]] = doc
        s.sources.append(str(doc["run_dir"]))
    for s in runs.values():
        s.scenes = sorted(s.per_scene)
        docs = [s.per_scene[k] for k in s.scenes]
        for col, (grp, key) in SYNTHETIC_COLUMNS.items():
            s.values[col] = _mean([d["metrics"].get(grp, {}).get(key) for d in docs])
        for cols, hidden in ((REAL_COLUMNS, False), (HIDDEN_COLUMNS, True)):
            for col, (grp, key) in cols.items():
                s.values[col] = _mean([d["metrics"].get(grp, {}).get(key) for d in docs if is_hidden(d) == hidden])
        for col, key in RUN_COLUMNS.items():
            s.values[col] = _mean([d.get(key) for d in docs])
        for col, key in MOTION_COLUMNS.items():
            s.values[col] = _mean([(d.get("motion") or {}).get(key) for d in docs])
        s.values["n_scenes"] = float(len(docs))
        s.values["n_scenes_gt"] = float(sum(bool(d["ground_truth"]) for d in docs))
    return runs
