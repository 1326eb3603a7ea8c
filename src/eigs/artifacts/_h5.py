"""The one HDF5 open-and-check of every artifact: the file exists, opens, and carries the expected format name and
version; otherwise an :class:`~eigs.errors.EigsError` naming the file and what to run."""

from __future__ import annotations

import os
from pathlib import Path

import h5py

from eigs.errors import H5_READ_ERRORS, EigsError


def open_artifact(path: str | os.PathLike, fmt: str, version: int, what: str, stage: str) -> h5py.File:
    """Open ``path`` for reading; ``fmt``/``version`` must match its ``format``/``version`` attributes. ``what``
    names the artifact in messages, ``stage`` the stage that writes it."""
    p = Path(path)
    if not p.exists():
        raise EigsError(p, f"no such {what} file (run the {stage} stage first)")
    try:
        f = h5py.File(p, "r")
    except OSError as err:
        raise EigsError(p, f"not a readable HDF5 file ({err})") from None
    try:
        ok = f.attrs.get("format") == fmt and int(f.attrs.get("version", -1)) == version
    except H5_READ_ERRORS as err:
        f.close()
        raise EigsError(p, f"corrupted {what} file, unreadable header ({err})") from None
    if not ok:
        f.close()
        raise EigsError(p, f"not an eigs {what} file of version {version}")
    return f
