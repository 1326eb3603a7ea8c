"""Which run fills which row of the paper's tables by default (the one place of these defaults): table → {row key →
run name}. Row keys are those of :mod:`eigs.tables.paper`; ``oracle`` is the upper-bound row. Table I has a row per
method of the catalog (:mod:`eigs.train.catalog`, its ``table1`` entries in its order; row key = run name = method
name) and the variants of :data:`TABLE1_VARIANTS`. The config's ``tables:`` section replaces a table's mapping as a
whole (:func:`table_rows`); a row whose run is not configured shows the paper's values only, so adding a method is
one ``runs:`` line under the name used here."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from eigs.train.catalog import METHODS

# Table I's rows beyond one per method: runs of a method with other options, after the method's own row
TABLE1_VARIANTS: dict[str, tuple[str, ...]] = {"eigs": ("eigs-literal", "eigs+")}
# Tables II-V and the ladder
DEFAULT_ROWS: dict[str, dict[str, str | None]] = {
    # Table II is the paper's ablation on `eigs` (the paper's reading); Tables III-V vary `eigs+` (EiGS with the
    # switches that pay, config/config.yaml): each of their rows changes one thing of it
    "table2": {"3dgs": "3dgs", "a": "eigs-a", "b": "eigs-b", "ours-minus": "eigs-minus", "ours": "eigs",
               "oracle": "oracle"},  # fmt: skip
    "table3": {"4": "eigs+", "6": "eigs-b6", "8": "eigs-b8", "oracle": "oracle"},
    "table4": {"64": "eigs-w64", "128": "eigs-w128", "256": "eigs+", "512": "eigs-w512", "oracle": "oracle"},
    "table5": {"2": "eigs-d2", "3": "eigs+", "4": "eigs-d4", "oracle": "oracle"},
    # not in the paper: what each addition beyond it buys, one switch at a time (config/ladder.yaml)
    "ladder": {"eigs": "eigs", "zero": "eigs-zero", "discrete": "eigs-zero-disc", "trapezoid": "eigs-zero-disc-trap",
               "latent": "eigs-zero-disc-trap-l", "sharp": "eigs+", "oracle": "oracle"},  # fmt: skip
}
# tables that exist only where one of their own rows (not shared with Tables I-V) has a configured run; the paper
# has no values for them
OPTIONAL_TABLES: dict[str, tuple[str, ...]] = {"ladder": ("zero", "discrete", "trapezoid", "latent")}


def table1_rows() -> dict[str, str | None]:
    """Table I's default rows: every catalog method with ``table1`` and its :data:`TABLE1_VARIANTS`."""
    keys = [k for name, spec in METHODS.items() if spec.table1 for k in (name, *TABLE1_VARIANTS.get(name, ()))]
    return {k: k for k in keys}


def method_label(key: str) -> str:
    """A row's label where the paper has none: its method's catalog ``label`` when the row key names a method (Table
    I: row key = method name), else the key."""
    spec = METHODS.get(key)
    return (spec.label or spec.name) if spec is not None else key


def default_rows() -> dict[str, dict[str, str | None]]:
    """Every table's default mapping: Table I's from the catalog, the others' :data:`DEFAULT_ROWS`."""
    return {"table1": table1_rows(), **{name: dict(rows) for name, rows in DEFAULT_ROWS.items()}}


def table_rows(overrides: dict[str, Any] | None = None) -> dict[str, dict[str, str | None]]:
    """The row mappings of every table: :func:`default_rows` with the tables of ``overrides`` (the config's
    ``tables:`` section) replacing theirs. Row keys are strings (YAML may read ``4:`` as an integer)."""
    out = default_rows()
    for name, rows in (overrides or {}).items():
        out[name] = {str(k): (None if v is None else str(v)) for k, v in rows.items()}
    return out


def configured_rows(overrides: dict[str, Any] | None, runs: Iterable[str]) -> dict[str, dict[str, str | None]]:
    """:func:`table_rows` with every row whose run is not among ``runs`` (the config's ``runs:``) set to None: such a
    row shows the paper's values only. This is the mapping ``eigs tables --tables`` takes (rule tables passes it)."""
    have = set(runs)
    out = {name: {row: (run if run in have else None) for row, run in rows.items()}
           for name, rows in table_rows(overrides).items()}  # fmt: skip
    return {name: rows for name, rows in out.items()
            if name not in OPTIONAL_TABLES or any(rows.get(k) for k in OPTIONAL_TABLES[name])}  # fmt: skip
