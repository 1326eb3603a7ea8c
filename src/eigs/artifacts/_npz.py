"""One NumPy-archive helper for the run folder's small ``.npz`` artifacts (``motion.npz``, ``cameras.npz``): written
atomically with a format name and version, read back whole with every failure one :class:`EigsError` naming the
file."""

from __future__ import annotations

import os
import zipfile
from pathlib import Path

import numpy as np

from eigs.errors import EigsError
from eigs.util.atomic import atomic_path


def write_npz(path: str | os.PathLike, fmt: str, version: int, arrays: dict[str, np.ndarray]) -> None:
    """``arrays`` and the ``format``/``version`` tags to ``path`` (temp file, then rename)."""
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.savez(f, format=np.array(fmt), version=np.array(version), **arrays)


def read_npz(path: str | os.PathLike, file_name: str, fmt: str, version: int, what: str) -> tuple[Path, dict]:
    """``(file, {name: array})`` of ``path`` (or of ``path / file_name`` when ``path`` is a folder), checked to be a
    ``fmt`` v``version`` archive; ``what`` names the file in errors ("no motion file")."""
    p = Path(path)
    if p.is_dir():
        p = p / file_name
    try:
        with np.load(p, allow_pickle=False) as z:
            if str(z["format"]) != fmt or int(z["version"]) != version:
                raise EigsError(p, f"not a {fmt} v{version} file")
            return p, {k: z[k] for k in z.files if k not in ("format", "version")}
    except FileNotFoundError:
        raise EigsError(p, f"no {what} file") from None
    except (OSError, ValueError, KeyError, zipfile.BadZipFile) as err:
        raise EigsError(p, f"unreadable {what} file ({err})") from None
