"""The numbers of the paper's Tables I–V, transcribed once (EiGS paper, §IV; /work/shared/paper/EiGS.md).

``PAPER[table][row][column]``: metric values as printed (PSNR in dB, SSIM, LPIPS-alex, BRISQUE), ``time_s`` training
time in seconds (the paper prints e.g. "3h25m" = 12,300 s), ``fps`` test-time frames per second (§IV-B text).
Rows of Table I follow the paper's method columns; the synthetic part (PSNR / SSIM / LPIPS, six E²NeRF synthetic
scenes, most likely novel views: ``../shared/docs/e2nerf-dataset.md`` §8) and the real part (BRISQUE, five E²NeRF real
scenes) list different methods, so a row may have only some of the columns. Table II's configuration marks are in
``CONFIG``. Row keys are what the config's ``tables:`` section maps to run names.
"""

from __future__ import annotations


def hm(hours: int, minutes: int) -> float:
    """Seconds of a time printed as ``{hours}h{minutes}m``."""
    return float(3600 * hours + 60 * minutes)


# Row order, labels and the paper's values. A label is how the paper names the row.
TABLES: dict[str, dict] = {
    "table1": {
        "title": "Table I: quantitative comparison (synthetic: PSNR / SSIM / LPIPS; real: BRISQUE)",
        "row_header": "Method",
        "rows": {
            "nerf": {"label": "NeRF", "psnr": 22.27, "ssim": 0.90, "lpips": 0.15, "brisque": 44.66},
            "deblur-nerf": {"label": "Deblur-NeRF", "psnr": 19.93, "ssim": 0.86, "lpips": 0.26, "brisque": 38.41},
            "edi-nerf": {"label": "EDI-NeRF", "psnr": 27.71, "ssim": 0.95, "lpips": 0.09, "brisque": 31.98},
            "e2nerf": {"label": "E²NeRF", "psnr": 29.56, "ssim": 0.96, "lpips": 0.07, "brisque": 30.26,
                       "fps": 0.04},  # fmt: skip
            "3dgs": {"label": "3DGS", "psnr": 20.27, "ssim": 0.86, "lpips": 0.15, "brisque": 38.89},
            "deblurring-gs": {"label": "Deblurring-GS", "psnr": 24.44, "ssim": 0.85, "lpips": 0.14, "brisque": 27.51},
            "deblurring-gs+": {"label": "Deblurring-GS+", "psnr": 22.72, "ssim": 0.84, "lpips": 0.15},
            "e2gs": {"label": "E2GS (w/ Est. Poses)", "psnr": 23.47, "ssim": 0.84, "lpips": 0.14, "brisque": 32.50},
            "evagaussians": {"label": "EvaGaussian", "psnr": 19.48, "ssim": 0.81, "lpips": 0.21},
            "besplat": {"label": "BeSplat", "brisque": 36.03},
            "bad-gaussians": {"label": "BAD-Gaussian", "psnr": 20.61, "ssim": 0.70, "lpips": 0.12, "brisque": 32.10},
            "eigs": {"label": "Ours (EiGS)", "psnr": 28.21, "ssim": 0.95, "lpips": 0.08, "brisque": 26.08,
                     "time_s": hm(3, 25), "fps": 190.0},  # fmt: skip
            # not in the paper: the literal reading of EiGS (latent poses only as ADE input features; docs/methods.md)
            "eigs-literal": {"label": "EiGS, literal reading (poses only as ADE features; not the paper's row)"},
            # not in the paper: EiGS with the beyond-the-paper switches that pay (docs/methods.md)
            "eigs+": {"label": "Ours+ (EiGS + our additions, docs/methods.md; not in the paper)"},
        },
    },
    "table2": {
        "title": "Table II: ablation of the losses and the ADE module (six synthetic scenes)",
        "row_header": "Method",
        "rows": {
            "3dgs": {"label": "3DGS", "psnr": 20.27, "ssim": 0.8653},
            "a": {"label": "(a) Deblurring-GS", "psnr": 24.10, "ssim": 0.8775},
            "b": {"label": "(b)", "psnr": 25.50, "ssim": 0.9009},
            "ours-minus": {"label": "Ours−", "psnr": 24.52, "ssim": 0.8868},
            "ours": {"label": "Ours", "psnr": 28.21, "ssim": 0.9452},
        },
    },
    "table3": {
        "title": "Table III: number of latent poses N",
        "row_header": "Latent poses N",
        "rows": {
            "4": {"label": "4", "psnr": 28.21, "ssim": 0.9452, "time_s": hm(3, 25)},
            "6": {"label": "6", "psnr": 28.81, "ssim": 0.9529, "time_s": hm(3, 28)},
            "8": {"label": "8", "psnr": 28.93, "ssim": 0.9540, "time_s": hm(5, 49)},
        },
    },
    "table4": {
        "title": "Table IV: ADE layer width",
        "row_header": "Layer width",
        "rows": {
            "64": {"label": "64", "psnr": 26.55, "ssim": 0.9135, "time_s": hm(3, 3)},
            "128": {"label": "128", "psnr": 27.02, "ssim": 0.9303, "time_s": hm(3, 16)},
            "256": {"label": "256", "psnr": 28.21, "ssim": 0.9452, "time_s": hm(3, 25)},
            "512": {"label": "512", "psnr": 28.05, "ssim": 0.9473, "time_s": hm(3, 25)},
        },
    },
    "table5": {
        "title": "Table V: ADE depth (layers)",
        "row_header": "Layer depth",
        "rows": {
            "2": {"label": "2", "psnr": 27.12, "ssim": 0.9389, "time_s": hm(3, 37)},
            "3": {"label": "3", "psnr": 28.21, "ssim": 0.9452, "time_s": hm(3, 25)},
            "4": {"label": "4", "psnr": 28.18, "ssim": 0.9536, "time_s": hm(3, 26)},
        },
    },
    # not in the paper: the ladder from the paper's EiGS to eigs+ (config/ladder.yaml); no paper values
    "ladder": {
        "title": "What each addition beyond the paper buys: EiGS (the paper's reading) to eigs+, one switch at a time",
        "row_header": "EiGS +",
        "rows": {
            "eigs": {"label": "EiGS (paper)"},
            "zero": {"label": "+ ADE last layer at zero"},
            "discrete": {"label": "+ discrete blur target"},
            "trapezoid": {"label": "+ trapezoid blur weights"},
            "latent": {"label": "+ latent-frame L1"},
            "sharp": {"label": "+ latent D-SSIM, weight by light (= eigs+)"},
        },
    },
}

# Table II's configuration columns: L_blur, L_event, ADE, L_consis ("+" with, "-" without).
CONFIG_COLUMNS = ("L_blur", "L_event", "ADE", "L_consis")
CONFIG = {
    "3dgs": "----",
    "a": "+-+-",
    "b": "+++-",
    "ours-minus": "+-++",
    "ours": "++++",
}

ORACLE_LABEL = "oracle (upper bound: sharp ground truth)"


def paper_value(table: str, row: str, column: str) -> float | None:
    """The paper's value of a cell, or None when the paper has none (a row or column it does not report)."""
    return TABLES.get(table, {}).get("rows", {}).get(row, {}).get(column)
