"""The SfM stage's report: ``report.json`` (the dict the phases fill, made JSON-safe) and ``report.png`` (camera
centres against the aligned ground truth, the relative latent errors per view)."""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from eigs.metrics.trajectory import Sim3

log = logging.getLogger(__name__)


def write_report(
    directory: Path,
    report: dict,
    c2w: np.ndarray,
    registered: np.ndarray,
    gt: np.ndarray | None,
    est_to_gt: Sim3 | None,
    plot: bool,
) -> None:
    """``report.json`` into ``directory``, and with ``plot`` ``report.png`` (a failed plot is a warning, never an
    error of the stage). ``c2w``: (V, L, 4, 4) canonical poses; ``registered``: (V, L); ``gt``: (V, L, 4, 4) ground
    truth or None; ``est_to_gt``: Sim(3) canonical estimate → ground truth or None."""
    if plot:
        try:
            plot_report(directory / "report.png", c2w, registered, gt, est_to_gt, report)
        except Exception as err:  # a plot never fails the stage
            log.warning("plot failed: %s", err)
    (directory / "report.json").write_text(json.dumps(jsonable(report), indent=2) + "\n")


def plot_report(
    path: Path, c2w: np.ndarray, registered: np.ndarray, gt: np.ndarray | None, est_to_gt: Sim3 | None, report: dict
) -> None:
    """``report.png``: camera centres (canonical x–y) against the aligned ground truth, the relative latent
    errors per moving view (report["accuracy"]["relative_latent"]) and the self-check's figures per view, as
    fractions of their limits (report["self_check"], COLMAP mode)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    est = c2w.reshape(-1, 4, 4)
    ok = np.all(np.isfinite(est), axis=(1, 2))
    reg = registered.reshape(-1)
    check = report.get("self_check")
    fig, axes = plt.subplots(1, 3 if check else 2, figsize=(16.5 if check else 11, 4.5))
    ax = axes[0]
    if gt is not None and est_to_gt is not None:
        canon_gt = est_to_gt.inverse().apply_c2w(gt.reshape(-1, 4, 4))
        g = canon_gt[:, :3, 3]
        ax.plot(g[:, 0], g[:, 1], ".", color="0.6", ms=4, label="ground truth (aligned)")
    e = est[ok][:, :3, 3]
    ax.plot(e[reg[ok], 0], e[reg[ok], 1], "b.", ms=4, label="registered")
    if (ok & ~reg).any():
        ax.plot(est[ok & ~reg][:, 0, 3], est[ok & ~reg][:, 1, 3], "rx", ms=5, label="interpolated")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(f"camera centres (canonical x–y), mode {report['mode']}")
    ax.legend(fontsize=8)
    ax = axes[1]
    rel = report.get("accuracy", {}).get("relative_latent")
    if rel:
        t = [np.nan if x is None else x for x in rel["translation_ratio_per_view"]]
        r = [np.nan if x is None else x for x in rel["rotation_ratio_per_view"]]
        x = np.arange(len(t))
        ax.bar(x - 0.2, t, 0.4, label="translation")
        ax.bar(x + 0.2, r, 0.4, label="rotation")
        ax.axhline(0.25, color="k", lw=0.8, ls="--")
        ax.set_xlabel("moving view")
        ax.set_ylabel("relative-pose error / true intra-exposure motion")
        ax.legend(fontsize=8)
        a = report["accuracy"]
        ax.set_title(
            f"ATE {a['ate_percent_of_extent']:.3f} % of extent; rot. median {a['rotation_error_deg_median']:.3f}°"
        )
    else:
        ax.axis("off")
        ax.text(0.5, 0.5, "no ground truth", ha="center", va="center")
    if check:
        _plot_self_check(axes[2], check)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _plot_self_check(ax, check: dict) -> None:
    """Path and turn errors per view over their limits (1 = the limit), failed views marked."""
    p = np.array([np.nan if x is None else x for x in check["path_error"]]) / check["limits"]["path_error"]
    r = np.array([np.nan if x is None else x for x in check["turn_error_deg"]]) / check["limits"]["turn_error_deg"]
    x = np.arange(p.size)
    ax.bar(x - 0.2, p, 0.4, label="path error / limit")
    ax.bar(x + 0.2, r, 0.4, label="turn error / limit")
    ax.axhline(1.0, color="k", lw=0.8, ls="--")
    for v in check["failed_views"]:
        ax.axvspan(v - 0.5, v + 0.5, color="r", alpha=0.15, lw=0)
    ax.set_xlabel("view (failed: red)")
    ax.set_ylabel("fraction of the limit")
    ax.legend(fontsize=8)
    verdict = "passed" if check["passed"] else "FAILED"
    ax.set_title(f"self-check {verdict}: {len(check['failed_views'])} view(s) off the camera path")


def jsonable(x: Any) -> Any:
    """``x`` with string keys, lists for tuples, Python scalars for NumPy ones and None for NaN and infinities."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [jsonable(v) for v in x]
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, float) and not np.isfinite(x):
        return None
    return x
