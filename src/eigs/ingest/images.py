"""Reading frames exactly: 8-bit gray or RGB, RGBA composited on black, truncated files refused."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from eigs.errors import EigsError
from eigs.util.progress import progress


def composite_on_black(rgba: np.ndarray) -> np.ndarray:
    """(H, W, C + 1) uint8 colour + alpha → (H, W, C) uint8, ``round(c · a / 255)`` (exact integer rounding)."""
    a = rgba[..., -1:].astype(np.uint32)
    c = rgba[..., :-1].astype(np.uint32)
    return ((c * a + 127) // 255).astype(np.uint8)


def read_image(path: Path) -> np.ndarray:
    """One 8-bit image → (H, W, C) uint8, C = 1 (gray) or 3 (RGB). Alpha is composited on black.

    Raises EigsError for a missing, truncated or corrupted file and for anything but 8 bits per channel.
    """
    from PIL import Image

    if not path.is_file():
        raise EigsError(path, "missing image")
    try:
        with Image.open(path) as im:
            im.load()
            mode = im.mode
            if mode == "P":
                im = im.convert("RGBA" if "transparency" in im.info else "RGB")
                mode = im.mode
            if mode not in ("L", "LA", "RGB", "RGBA"):
                raise EigsError(path, f"image mode {mode!r} is not 8-bit gray or RGB(A)")
            a = np.asarray(im, dtype=np.uint8)
    except EigsError:
        raise
    except Exception as err:  # PIL raises OSError, SyntaxError, ValueError, ... for bad files
        raise EigsError(path, f"not a readable image, truncated or corrupted ({err})") from None
    if a.ndim == 2:
        a = a[:, :, None]
    if mode in ("LA", "RGBA"):
        a = composite_on_black(a)
    return np.ascontiguousarray(a)


def read_images(paths: Sequence[Path], desc: str = "frames") -> np.ndarray:
    """Images of one size and channel count → (N, H, W, C) uint8; EigsError naming the first that differs."""
    if not paths:
        raise ValueError("no images")
    first = read_image(paths[0])
    out = np.empty((len(paths), *first.shape), dtype=np.uint8)
    out[0] = first
    for i, p in enumerate(progress(paths[1:], desc=desc, total=len(paths) - 1, unit="img"), start=1):
        a = read_image(p)
        if a.shape != first.shape:
            raise EigsError(
                p,
                f"image is {a.shape[1]}×{a.shape[0]}×{a.shape[2]} but {paths[0].name} is "
                f"{first.shape[1]}×{first.shape[0]}×{first.shape[2]} (W×H×C)",
            )
        out[i] = a
    return out
