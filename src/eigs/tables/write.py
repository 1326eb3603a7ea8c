"""Write a :class:`~eigs.tables.build.Table` as CSV, Markdown and LaTeX (atomically).

Every cell shows ours and, in parentheses, the paper's value: ``24.10 (24.44)``; "–" where there is none. Best and
second best (the paper marks them red and blue) are **bold** and _underlined_ in Markdown, ``\\best{}`` and
``\\second{}`` in LaTeX (defined at the top of the file with ``\\providecommand``, red and blue with xcolor), ``1``
and ``2`` in the CSV's ``*_rank`` columns; ranks of the paper's values are marked the same way inside the
parentheses. The CSV keeps full precision; Markdown and LaTeX round to each column's decimals.
"""

from __future__ import annotations

import csv
import io
import math
import os
from pathlib import Path

from eigs.tables.build import ORACLE_DELTAS, Column, Row, Table
from eigs.tables.paper import CONFIG_COLUMNS
from eigs.util.atomic import atomic_path

DASH = "–"


def fmt_time(seconds: float | None) -> str:
    """``3h25m`` from 1 h on, ``5m07s`` from 1 min on, else ``12.3s``; "–" for None."""
    if seconds is None or not math.isfinite(seconds):
        return DASH
    s = int(round(seconds))
    if seconds >= 3600:
        m = int(round(seconds / 60.0))
        return f"{m // 60}h{m % 60:02d}m"
    if seconds >= 60:
        return f"{s // 60}m{s % 60:02d}s"
    return f"{seconds:.1f}s"


def fmt(v: float | None, col: Column, paper: bool = False) -> str:
    """A value as displayed: the column's decimals (the paper's printed precision for paper values), times as
    ``3h25m``, counts with thousands separators."""
    if v is None or not math.isfinite(v):
        return DASH
    decimals = col.paper_decimals if paper and col.paper_decimals is not None else col.decimals
    if decimals is None:
        return fmt_time(v)
    if decimals == 0:
        return f"{v:,.0f}"
    return f"{v:.{decimals}f}"


def fmt_delta(v: float | None, decimals: int) -> str:
    return DASH if v is None else f"{v:+.{decimals}f}"


def _mark(text: str, rank: int | None, style: str) -> str:
    if rank is None or text == DASH:
        return text
    if style == "md":
        return f"**{text}**" if rank == 1 else f"<u>{text}</u>"
    return f"\\best{{{text}}}" if rank == 1 else f"\\second{{{text}}}"


def cell_text(row: Row, col: Column, style: str) -> str:
    c = row.cells[col.key]
    ours = _mark(fmt(c.ours, col), c.rank, style)
    paper = _mark(fmt(c.paper, col, paper=True), c.paper_rank, style)
    return f"{ours} ({paper})"


def shown_columns(t: Table) -> list[Column]:
    return [c for c in t.columns if c.shown]


def delta_decimals(key: str) -> int:
    return 2 if key == "psnr" else 4


def header(t: Table) -> list[str]:
    cols = [t.row_header]
    if t.name == "table2":
        cols += list(CONFIG_COLUMNS)
    cols += [f"{c.label} ours (paper)" for c in shown_columns(t)]
    cols += ["Δ oracle PSNR", "scenes", "source"]
    return cols


def cells(t: Table, row: Row, style: str) -> list[str]:
    out = [row.label]
    if t.name == "table2":
        out += list(row.config) if row.config else [""] * len(CONFIG_COLUMNS)
    out += [cell_text(row, c, style) for c in shown_columns(t)]
    out += [fmt_delta(row.d_oracle.get("psnr"), 2), str(row.n_scenes), row.source or DASH]
    return out


def to_markdown(t: Table) -> str:
    def esc(s: str) -> str:
        return s.replace("|", "\\|")

    lines = [f"**{t.title}**", "", "| " + " | ".join(header(t)) + " |", "|" + "---|" * len(header(t))]
    for r in t.rows:
        lines.append("| " + " | ".join(esc(x) for x in cells(t, r, "md")) + " |")
    lines += ["", NOTE, *(f"\n{n}" for n in t.notes), ""]
    return "\n".join(lines)


NOTE = (
    "Each cell: ours (the paper's value); **best**, <u>second best</u> among the methods (the oracle row, trained on "
    "the sharp ground truth, is an upper bound and not ranked); Δ oracle PSNR = ours − oracle (dB), the mean over the "
    "scenes both runs have; PSNR / SSIM "
    "(3dgs lineage) / LPIPS-alex / sharpness (the high-frequency power ratio against the ground truth: 1 as sharp, "
    "below smoother, above noisier; not ranked) / HF coherence (the ground truth's detail above 0.25 cycles/pixel "
    "that the render reproduces: 1 all of it, 0 none; noise does not raise it; not ranked) are means over the "
    "synthetic scenes at the novel views, BRISQUE over "
    "the scenes "
    "without ground truth (where there is none, over the simulated recordings with a hidden ground truth, as the "
    "note below says); train time and FPS are means per scene; source: the run folders."
)

_TEX = {
    "\\": "\\textbackslash{}",
    "&": "\\&",
    "%": "\\%",
    "$": "\\$",
    "#": "\\#",
    "_": "\\_",
    "{": "\\{",
    "}": "\\}",
    "~": "\\textasciitilde{}",
    "^": "\\textasciicircum{}",
    "²": "$^2$",
    "−": "$-$",
    "↑": "$\\uparrow$",
    "↓": "$\\downarrow$",
    "Δ": "$\\Delta$",
    "–": "--",
}


def tex_escape(s: str) -> str:
    return "".join(_TEX.get(ch, ch) for ch in s)


def to_latex(t: Table) -> str:
    head = header(t)
    lines = [
        f"% {t.title}. Generated by `eigs tables`; needs \\usepackage{{xcolor}}.",
        "\\providecommand{\\best}[1]{\\textcolor{red}{#1}}",
        "\\providecommand{\\second}[1]{\\textcolor{blue}{#1}}",
        "\\begin{tabular}{" + "l" * len(head) + "}",
        "\\hline",
        " & ".join(tex_escape(h) for h in head) + " \\\\",
        "\\hline",
    ]
    for r in t.rows:
        # number cells hold only digits, signs, "h m s" and parentheses besides the \best{}/\second{} markup
        row = [x if ("\\best{" in x or "\\second{" in x) else tex_escape(x) for x in cells(t, r, "tex")]
        lines.append(" & ".join(row).replace("–", "--") + " \\\\")
    lines += ["\\hline", "\\end{tabular}", *(f"% {n}" for n in t.notes), ""]
    return "\n".join(lines)


def csv_header(t: Table) -> list[str]:
    cols = ["table", "row", "label", "role", "run", "n_scenes"]
    if t.name == "table2":
        cols += list(CONFIG_COLUMNS)
    for c in t.columns:  # ours under the key of its values (brisque_sim in BRISQUE's place), the paper's under key
        ours = c.source or c.key
        cols += [ours, f"{c.key}_paper", f"{ours}_rank", f"{c.key}_paper_rank"]
    cols += [f"d_oracle_{k}" for k in ORACLE_DELTAS if any(k == c.key for c in t.columns)]
    cols += ["source"]
    return cols


def to_csv(t: Table) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(csv_header(t))

    def num(v: float | None) -> str:
        return "" if v is None or not math.isfinite(v) else repr(float(v))

    for r in t.rows:
        out: list[str] = [t.name, r.key, r.label, r.role, r.run or "", str(r.n_scenes)]
        if t.name == "table2":
            out += list(r.config) if r.config else [""] * len(CONFIG_COLUMNS)
        for c in t.columns:
            cell = r.cells[c.key]
            out += [num(cell.ours), num(cell.paper), str(cell.rank or ""), str(cell.paper_rank or "")]
        out += [num(r.d_oracle.get(k)) for k in ORACLE_DELTAS if any(k == c.key for c in t.columns)]
        out.append(r.source)
        w.writerow(out)
    return buf.getvalue()


def write_table(t: Table, out_dir: str | os.PathLike) -> list[Path]:
    """Write ``{name}.csv``, ``.md`` and ``.tex`` into ``out_dir``; returns the paths."""
    out = []
    for ext, text in (("csv", to_csv(t)), ("md", to_markdown(t)), ("tex", to_latex(t))):
        p = Path(out_dir) / f"{t.name}.{ext}"
        with atomic_path(p) as tmp:
            tmp.write_text(text)
        out.append(p)
    return out
