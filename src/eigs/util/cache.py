"""The one cache directory of eigs (rasterizer builds, resource downloads).

``$EIGS_CACHE_DIR`` when set, else ``$XDG_CACHE_HOME/eigs``, else ``~/.cache/eigs``.
"""

from __future__ import annotations

import os
from pathlib import Path

ENV = "EIGS_CACHE_DIR"


def cache_dir() -> Path:
    """Root of eigs's caches (not created here)."""
    if os.environ.get(ENV):
        return Path(os.environ[ENV])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "eigs"
