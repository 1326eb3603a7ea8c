"""Does camera refinement in training pay? (issue 44): the studies config/camera_refine.yaml (six 128×96 scenes) and
config/camera_refine_d346.yaml (d346-blocks, d346-chair, d346-drums), read from their ``metrics.json`` files.

For `edi-3dgs`, `eigs+` and the oracle, each trained as configured and again with ``camera_refine`` (``<run>-cam``),
per scene: novel-view PSNR (dB) and LPIPS under both evaluation protocols — "today's" (the test cameras SfM
registered) and "test poses refined" (each test camera refined against its image on the frozen model,
``evaluate: test_pose_iters``; docs/evaluation.md) — and the refined run's training cameras against the ground truth
before and after refinement (ATE in % of the extent, median rotation error; ``cameras`` in metrics.json). The gain
of the switch is ``<run>-cam`` − ``<run>`` under each protocol. Every number names its protocol.

Run: ``.venv/bin/python bench/camera_refine_report.py [--results DIR ...] [--out DIR]`` (DIR: a results folder or a
suite ledger; default ``results``); the section is ``camera-refine`` in docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench._report import fixed, results_roots, table, write_section  # noqa: E402

RUNS = ("edi-3dgs", "eigs+", "oracle")
SCENES = ("blocks", "chair", "dish", "drums", "spheres", "tree", "d346-blocks", "d346-chair", "d346-drums")
PROTOCOLS = {"novel": "today's", "novel_pose_opt": "test poses refined"}


def read(results: list[Path]) -> dict[tuple[str, str], dict]:
    """(scene, run) → metrics document, for the study's scenes and runs (with and without ``-cam``)."""
    out: dict[tuple[str, str], dict] = {}
    names = set(RUNS) | {f"{r}-cam" for r in RUNS}
    for root in results:
        for path in sorted(root.glob("*/b4/eval/*/metrics.json")):
            scene, run = path.parts[-5], path.parts[-2]
            if scene in SCENES and run in names:
                out[(scene, run)] = json.loads(path.read_text())
    return out


def value(doc: dict | None, group: str, key: str) -> float:
    v = ((doc or {}).get("metrics") or {}).get(group, {}).get(key)
    return float(v) if v is not None else math.nan


def cameras(doc: dict | None, when: str) -> tuple[float, float]:
    c = ((doc or {}).get("cameras") or {}).get(when) or {}
    return float(c.get("ate_percent_of_extent", math.nan)), float(c.get("rotation_error_deg_median", math.nan))


def report(docs: dict[tuple[str, str], dict], trained_on: dict[tuple[str, str], str] | None = None) -> tuple[str, dict]:
    """The section's text and data; ``trained_on``: (scene, run) → the machine its training ran on."""
    scenes = [s for s in SCENES if any((s, r) in docs for r in RUNS)]
    rows, data = [], {}
    for run in RUNS:
        for scene in scenes:
            plain, cam = docs.get((scene, run)), docs.get((scene, f"{run}-cam"))
            if plain is None and cam is None:
                continue
            rec = {}
            for group in PROTOCOLS:
                for key in ("psnr", "lpips_alex"):
                    rec[f"{group}.{key}"] = value(plain, group, key)
                    rec[f"{group}.{key}.cam"] = value(cam, group, key)
            (ate0, rot0), (ate1, rot1) = cameras(cam, "before"), cameras(cam, "after")
            rec |= {"ate_before": ate0, "ate_after": ate1, "rot_before": rot0, "rot_after": rot1}
            data[f"{scene}/{run}"] = rec
            gain = {g: rec[f"{g}.psnr.cam"] - rec[f"{g}.psnr"] for g in PROTOCOLS}
            rows.append([f"`{run}`", scene,
                         fixed(rec["novel.psnr"]), fixed(rec["novel.psnr.cam"]), fixed(gain["novel"], sign=True),
                         fixed(rec["novel_pose_opt.psnr"]), fixed(rec["novel_pose_opt.psnr.cam"]),
                         fixed(gain["novel_pose_opt"], sign=True),
                         fixed(rec["novel.lpips_alex"], 3), fixed(rec["novel.lpips_alex.cam"], 3),
                         fixed(ate0), fixed(ate1), fixed(rot0), fixed(rot1),
                         machine_of(trained_on or {}, scene, run)])  # fmt: skip
    headers = ["run", "scene", "today's", "today's, cam", "gain", "test poses refined", "refined, cam", "gain",
               "LPIPS", "LPIPS, cam", "ATE % before", "after", "rot ° before", "after", "trained on"]  # fmt: skip
    body = [
        "Novel-view PSNR (dB) of each run as configured and with `camera_refine` (`-cam`) under both evaluation "
        "protocols (docs/evaluation.md): *today's* renders the test cameras SfM registered; *test poses refined* "
        "first refines each test camera against its image on the frozen model (100 iterations). LPIPS under today's "
        "protocol. ATE (% of the scene extent) and the median rotation error of the refined run's training cameras "
        "against the ground truth, before and after refinement (each set Sim(3)-aligned on its own). "
        "Studies: config/camera_refine.yaml (128×96) and config/camera_refine_d346.yaml (346×260); one seed. "
        "'trained on': the machine of the row's two trainings (the ledger's jobs.csv). COLMAP reconstructs the same "
        'inputs differently on different machines (docs/sfm.md, "d346-blocks on another machine"), so rows of one '
        "scene trained on different machines stand on different SfM poses: compare a row's gain, not rows.",
        "",
        table(headers, rows),
    ]
    for run in RUNS:
        for suite, names in (("128×96", [s for s in scenes if not s.startswith("d346")]),
                             ("346×260", [s for s in scenes if s.startswith("d346")])):  # fmt: skip
            gains = {g: [data[f"{s}/{run}"][f"{g}.psnr.cam"] - data[f"{s}/{run}"][f"{g}.psnr"]
                         for s in names if f"{s}/{run}" in data] for g in PROTOCOLS}  # fmt: skip
            gains = {g: [x for x in v if math.isfinite(x)] for g, v in gains.items()}
            if any(gains.values()):
                parts = [f"{label} {fixed(min(gains[g]), sign=True)} to {fixed(max(gains[g]), sign=True)} dB "
                         f"(mean {fixed(sum(gains[g]) / len(gains[g]), sign=True)}, {len(gains[g])} scenes)"
                         for g, label in PROTOCOLS.items() if gains[g]]  # fmt: skip
                body.append(f"\n`{run}` at {suite}, gain of the switch: " + "; ".join(parts) + ".")
    return "\n".join(body), data


def trainings(ledgers: list[Path]) -> dict[tuple[str, str], str]:
    """(scene, run) → the machine its training ran on (short name), from the ledgers' jobs.csv (none: empty)."""
    from bench.suite_ledger import read_jobs_csv

    out: dict[tuple[str, str], str] = {}
    for ledger in ledgers:
        for job in read_jobs_csv(ledger):
            kind, scene, run = job["job"].split(":", 2)
            if kind == "train":
                name = job["machine"].split(",")[0].replace("(R)", "").replace(" Processor", "")
                out[(scene, run)] = " ".join(name.split())
    return out


def machine_of(trained_on: dict[tuple[str, str], str], scene: str, run: str) -> str:
    """The machine of a row's pair of trainings ("A / B" where the two ran on different machines; – unknown)."""
    names = [trained_on.get((scene, r)) for r in (run, f"{run}-cam")]
    known = sorted({n for n in names if n})
    return " / ".join(known) if known else "–"


def main() -> None:
    args, roots = results_roots(argparse.ArgumentParser(description=__doc__.splitlines()[0]))
    docs = read(roots)
    if not docs:
        raise SystemExit(f"camera_refine_report.py: no metrics.json of the study's runs under {args.results}")
    body, data = report(docs, trainings([r.parent for r in roots]))
    write_section("camera-refine", "Camera refinement in training: both protocols (issue 44)", body, data, args.out)


if __name__ == "__main__":
    main()
