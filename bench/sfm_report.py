"""Summarise the SfM reports (``results/<scene>/b<B>/sfm/report.json``) of finished runs against the SfM targets:
registered fraction, ATE (% of the extent), rotation error, relative latent-pose ratios, test cameras and their
reprojection error. Used to check that SfM still meets its targets after a scene change (e.g. the blur calibration).

Run: ``.venv/bin/python bench/sfm_report.py results/*/b4/sfm [--title TEXT]`` → Markdown table on stdout.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

TARGETS = (
    "targets: registered ≥ 95 %, ATE ≤ 1 % of the extent, relative latent ratios ≤ 0.25 (median over views), "
    "test reprojection ≤ 0.5 px"
)


def row(report: dict) -> list[str]:
    reg, acc, test = report["registration"], report.get("accuracy") or {}, report.get("test_cameras") or {}
    rel = acc.get("relative_latent") or {}

    def f(x: float | None, fmt: str) -> str:
        return "n/a" if x is None else format(x, fmt)

    return [
        report["scene"],
        f"{reg['registered']}/{reg['images']} ({100 * reg['fraction']:.1f} %)",
        f(acc.get("ate_percent_of_extent"), ".3f"),
        f(acc.get("rotation_error_deg_median"), ".3f"),
        f(rel.get("translation_ratio_median"), ".3f") + " / " + f(rel.get("rotation_ratio_median"), ".3f"),
        f(max(rel.get("translation_ratio_per_view") or [float("nan")]), ".3f")
        + " / "
        + f(max(rel.get("rotation_ratio_per_view") or [float("nan")]), ".3f"),
        f"{test.get('registered', 'n/a')}/{test.get('count', 'n/a')}",
        f(test.get("reprojection_error_px_median"), ".3f"),
    ]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sfm_dirs", nargs="+", type=Path)
    args = ap.parse_args()
    head = ["scene", "registered", "ATE %", "rot. err. °", "rel. latent t / R (median view)", "(worst view)",
            "test registered", "test reproj. px"]  # fmt: skip
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for d in sorted(args.sfm_dirs):
        print("| " + " | ".join(row(json.loads((d / "report.json").read_text()))) + " |")
    print()
    print(TARGETS)


if __name__ == "__main__":
    main()
