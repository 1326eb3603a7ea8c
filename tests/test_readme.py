"""README drift: every measured number in README.md comes from a generated block, none is typed by hand.

The rule (what :func:`typed_numbers` flags), applied to README.md outside the allowed regions:

* a decimal fraction, ``29.57``, ``0.13``, ``+8.88``, ``−3.14`` — except a version (``3.11.7``, three parts or more;
  ``Python 3.11``, ``torch 2.13.0``, ``v1.2`` and ``==1.2``);
* a number with a unit of a measurement: dB, %, ×/x (a speed-up), time (``s``, ``ms``, ``min``, ``minutes``, ``h``,
  ``hours``, ``sec``, ``seconds``, ``CPU minutes``), memory (``KB``/``MB``/``GB``/``GiB``/``MiB``), frame rate
  (``fps``/``FPS``);
* a count of work done: ``N jobs``, ``N trainings``, ``N evaluations``.

Allowed everywhere: plain integers (``six scenes``, ``B = 4, 6, 8``, ``issue 18``, ``Table I``), dates
(``2026-11-26``), sizes (``346×260``), and whatever stands in these regions: a generated block between
``<!-- NAME:begin -->`` and ``<!-- NAME:end -->`` (``bench/suite_report.py --readme`` writes ``suite-report``), fenced
code blocks, inline code spans (commands and options such as ``--cores 2``), HTML comments and link or image targets.
A number the README needs goes into a generated block (change its generator) or stays in the document that measures it.
"""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

BLOCK = re.compile(r"<!--\s*([\w.-]+):begin\s*-->.*?<!--\s*\1:end\s*-->", re.S)
FENCE = re.compile(r"^(```|~~~).*?^\1[ \t]*$", re.S | re.M)
COMMENT = re.compile(r"<!--.*?-->", re.S)
CODE = re.compile(r"(`+)(?!`).*?(?<!`)\1(?!`)", re.S)
LINK_TARGET = re.compile(r"\]\([^)]*\)")
UNIT = (r"dB|%|×|x\b|ms\b|s\b|sec\b|seconds\b|min\b|minutes\b|CPU minutes\b|h\b|hours\b|[KMG]i?B\b|fps\b|FPS\b"
        r"|jobs\b|trainings\b|evaluations\b")  # fmt: skip
NUMBER = r"[+−-]?\d+(?:[.,]\d+)?"
MEASURED = re.compile(rf"(?<![\w.]){NUMBER}\s*(?:{UNIT})")
DECIMAL = re.compile(r"(?<![\w.=])[+−-]?\d+\.\d+(?![\w.])")
VERSION_BEFORE = re.compile(r"(?:Python|torch|CUDA|gsplat|numpy|version|v|==)\s*$", re.I)
DATE = re.compile(r"\b\d{4}-\d{2}-\d{2}\b")
SIZE = re.compile(r"\b\d+\s*×\s*\d+\b")


def _blank(text: str, pattern: re.Pattern) -> str:
    """``text`` with every match of ``pattern`` replaced by spaces (newlines kept, so line numbers stay)."""
    return pattern.sub(lambda m: re.sub(r"[^\n]", " ", m.group(0)), text)


def typed_numbers(text: str) -> list[tuple[int, str]]:
    """(line number, number with its unit) of every hand-typed number of ``text`` by the module's rule, in order."""
    for pattern in (BLOCK, FENCE, COMMENT, CODE, LINK_TARGET, DATE, SIZE):
        text = _blank(text, pattern)
    found: list[tuple[int, int, str]] = []
    for m in MEASURED.finditer(text):
        found.append((m.start(), m.end(), m.group(0)))
    for m in DECIMAL.finditer(text):
        if VERSION_BEFORE.search(text[max(0, m.start() - 12) : m.start()]):
            continue
        if any(s <= m.start() < e for s, e, _ in found):
            continue
        found.append((m.start(), m.end(), m.group(0)))
    return [(text.count("\n", 0, s) + 1, t.strip()) for s, _, t in sorted(found)]


def test_readme_has_no_hand_typed_numbers():
    bad = typed_numbers((REPO / "README.md").read_text())
    assert not bad, "numbers typed outside a generated block (put them in one, or point at it): " + "; ".join(
        f"line {n}: {t!r}" for n, t in bad
    )


def test_readme_has_the_suite_report_block():
    text = (REPO / "README.md").read_text()
    assert text.count("<!-- suite-report:begin -->") == 1 and text.count("<!-- suite-report:end -->") == 1
    assert text.index("<!-- suite-report:begin -->") < text.index("<!-- suite-report:end -->")


def test_the_checker_flags_a_planted_number_in_a_copy_of_the_readme():
    """The drift of issue 35 planted back into prose of a copy: each is found, on its line; the same text inside
    the generated block, a code span or a fenced block is not."""
    text = (REPO / "README.md").read_text()
    anchor = "## Two commands\n"
    assert anchor in text
    line = text[: text.index(anchor)].count("\n") + 2
    planted = ("novel-view PSNR means eigs+ 29.78, +8.88 dB over 3dgs, 0.13 dB below the oracle; 364 jobs, "
               "682 CPU minutes, 5.70 h on 2 cores, 23 % faster, 3× per step.\n")  # fmt: skip
    got = typed_numbers(text.replace(anchor, anchor + planted))
    assert got == [(line, "29.78"), (line, "+8.88 dB"), (line, "0.13 dB"), (line, "364 jobs"),
                   (line, "682 CPU minutes"), (line, "5.70 h"), (line, "23 %"), (line, "3×")], got  # fmt: skip
    inside = text.replace("<!-- suite-report:end -->", planted + "<!-- suite-report:end -->")
    inside = inside.replace(anchor, anchor + "`29.78 dB` and\n```\n364 jobs, 5.70 h\n```\n")
    assert typed_numbers(inside) == []


def test_the_rule_allows_versions_dates_sizes_and_plain_integers():
    ok = ("Python 3.11, torch 2.13.0, Python 3.11.7, ==1.1.5, v0.1.0, on 2026-11-26, 346×260 pixels, six scenes, "
          "B = 4, 6, 8, issue 18, Table III, `--cores 2`, [x](docs/a1.5.md), <!-- 1.5 dB -->\n")  # fmt: skip
    assert typed_numbers(ok) == []
    assert typed_numbers("the mean rose to 1.5 and took 30 s\nthen 12 min, 9 jobs, 60 fps\n") == [
        (1, "1.5"), (1, "30 s"), (2, "12 min"), (2, "9 jobs"), (2, "60 fps")]  # fmt: skip
