"""Progress bars: one place decides whether and how they are shown."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable, Iterator
from typing import TypeVar

from tqdm import tqdm

T = TypeVar("T")


def progress(iterable: Iterable[T], desc: str, total: int | None = None, unit: str = "it") -> Iterator[T]:
    """Wrap ``iterable`` in a progress bar on stderr.

    Bars are disabled when ``EIGS_PROGRESS=0``; under a non-interactive stderr (Snakemake logs) they
    still print, but at most every 5 s so log files stay small; ``eigs status`` reads them back from the logs
    (eigs.util.status; docs/development.md, "Progress while Snakemake runs").
    """
    disable = os.environ.get("EIGS_PROGRESS", "1") == "0"
    interactive = sys.stderr.isatty()
    return iter(
        tqdm(
            iterable,
            desc=desc,
            total=total,
            unit=unit,
            disable=disable,
            mininterval=0.1 if interactive else 5.0,
            dynamic_ncols=interactive,
            file=sys.stderr,
        )
    )
