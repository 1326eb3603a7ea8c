"""The SfM self-check (eigs.sfm.selfcheck) over finished reconstructions, beside their ground-truth accuracy: the
table of docs/sfm.md, "Self-check". Each argument is an `sfm/` folder (poses.h5, report.json) or a folder holding
one; the check is computed again from poses.h5 on the latents COLMAP registered (the stage's own verdict from
report.json where the stage dropped views, whose poses are then gone).

Run: ``.venv/bin/python bench/sfm_selfcheck.py results/*/b*/sfm /tmp/variants/*/sfm [--names a b …]``
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from eigs.artifacts.poses import read_poses
from eigs.sfm.selfcheck import self_check


def verdict(sfm: Path) -> dict:
    """The self-check computed from poses.h5 on the latents COLMAP registered — exactly the stage's when it dropped
    no view (or ran with ``self_check: false``, or before the check existed); else the stage's own verdict from
    report.json, since the dropped views' poses are gone."""
    rep = json.loads((sfm / "report.json").read_text())
    if rep.get("registration", {}).get("dropped_by_self_check"):
        return rep["self_check"]
    poses = read_poses(sfm / "poses.h5")
    registered = poses.registered & ~poses.interpolated
    return self_check(poses.c2w, registered, poses.timestamps_us, rep.get("models")).summary()


def row(sfm: Path, name: str) -> str:
    rep = json.loads((sfm / "report.json").read_text())
    sc = verdict(sfm)
    acc = rep.get("accuracy") or {}
    ate = acc.get("ate_percent_of_extent")
    rot = acc.get("rotation_error_deg_median")

    def worst(key: str) -> float:
        vals = [x for x in sc[key] if x is not None]
        return max(vals) if vals else float("nan")

    reg = rep["registration"]
    return (
        f"| {name} | {reg['registered']}/{reg['images']} | {', '.join(str(m) for m in rep.get('models', []))} | "
        f"{'–' if ate is None else f'{ate:.2f}'} | {'–' if rot is None else f'{rot:.2f}'} | "
        f"{worst('path_error'):.2f} | {worst('turn_error_deg'):.1f} | "
        f"{', '.join(str(v) for v in sc['failed_views']) or '–'} | {'pass' if sc['passed'] else '**fail**'} |"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folders", nargs="+", type=Path)
    ap.add_argument("--names", nargs="*", help="row names (default: the folders)")
    args = ap.parse_args()
    names = args.names or [str(f) for f in args.folders]
    print("| reconstruction | registered | models | ATE % | rot. err. ° (median) | max path error (steps) | "
          "max turn ° | views failed | self-check |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|")
    for folder, name in zip(args.folders, names, strict=True):
        sfm = folder if (folder / "poses.h5").is_file() else folder / "sfm"
        print(row(sfm, name))


if __name__ == "__main__":
    main()
