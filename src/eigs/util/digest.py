"""Content digests of a stage's input files: what a cache (a training checkpoint) was made from."""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from pathlib import Path

CHUNK = 1 << 20  # bytes read at a time


def _update_with_file(h: hashlib._Hash, path: Path) -> None:
    with path.open("rb") as f:
        while block := f.read(CHUNK):
            h.update(block)


def files_digest(inputs: Mapping[str, str | Path]) -> str:
    """SHA-256 (hex) over ``inputs`` (name → file or folder): each name, then each file's path relative to its input
    and its bytes, folders walked in sorted order. Equal digests mean byte-identical inputs under the same names; a
    missing input counts as its own state (``missing``), so the digest of an incomplete set never equals a complete
    one's. Reads every byte (about 1 GB/s)."""
    h = hashlib.sha256()
    for name in sorted(inputs):
        root = Path(inputs[name])
        h.update(f"\0input\0{name}\0".encode())
        if root.is_file():
            _update_with_file(h, root)
        elif root.is_dir():
            for path in sorted(p for p in root.rglob("*") if p.is_file()):
                h.update(f"\0file\0{path.relative_to(root).as_posix()}\0".encode())
                _update_with_file(h, path)
        else:
            h.update(b"\0missing\0")
    return h.hexdigest()
