"""Real photographs as textures: scikit-image's bundled sample images, linearised on load.

Only images that ship inside the scikit-image wheel are used (never the ones it fetches on demand with pooch),
so generation works offline. Every texture is converted sRGB → linear intensity once, here; the renderer
works in linear intensity from then on (see docs/synthetic.md, "Intensity domain").
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from eigs.errors import EigsError
from eigs.util.image import srgb_to_linear

# name -> (skimage.data function, colour photo?). All of these ship in the wheel (skimage/data/*.png|jpg).
_SOURCES: dict[str, str] = {
    "astronaut": "astronaut",
    "brick": "brick",
    "camera": "camera",
    "chelsea": "chelsea",
    "coffee": "coffee",
    "coins": "coins",
    "colorwheel": "colorwheel",
    "grass": "grass",
    "gravel": "gravel",
    "hubble": "hubble_deep_field",
    "ihc": "immunohistochemistry",
    "moon": "moon",
    "retina": "retina",
    "rocket": "rocket",
    "text": "text",
}
TEXTURE_NAMES: tuple[str, ...] = tuple(sorted(_SOURCES))


def _load_raw(name: str) -> np.ndarray:
    import skimage.data

    if name not in _SOURCES:
        raise EigsError(None, f"unknown texture {name!r}; available: {', '.join(TEXTURE_NAMES)}")
    img = np.asarray(getattr(skimage.data, _SOURCES[name])())
    if img.dtype == bool:
        img = img.astype(np.uint8) * 255
    if img.ndim == 2:
        img = np.repeat(img[:, :, None], 3, axis=2)
    return img[:, :, :3]


@lru_cache(maxsize=64)
def load_texture(name: str, size: int = 128, crop: tuple[float, float, float] = (0.0, 0.0, 1.0)) -> np.ndarray:
    """Texture ``name`` as (size, size, 3) float32 **linear** intensity in [0, 1].

    The photograph is centre-cropped to a square, then to the window ``crop`` = (x0, y0, side) given as fractions
    of that square (x0 + side ≤ 1, y0 + side ≤ 1), low-pass resized to ``size`` (anti-aliased, so a texture seen
    at ~1 texel per pixel does not shimmer) and sRGB-decoded. Grey photographs are replicated to 3 channels
    (primitives may tint them). Cached; treat the result as read-only.
    """
    from skimage.transform import resize

    cx0, cy0, side = (float(c) for c in crop)
    if not (0.0 < side <= 1.0 and 0.0 <= cx0 <= 1.0 - side + 1e-9 and 0.0 <= cy0 <= 1.0 - side + 1e-9):
        raise EigsError(None, f"texture {name!r}: crop {crop} must be (x0, y0, side) with 0 < side ≤ 1 and the "
                        "window inside the photograph")
    img = _load_raw(name).astype(np.float64) / 255.0
    h, w = img.shape[:2]
    s = min(h, w)
    y0, x0 = (h - s) // 2, (w - s) // 2
    img = img[y0 : y0 + s, x0 : x0 + s]
    n = max(int(round(side * s)), 2)
    ox, oy = min(int(round(cx0 * s)), s - n), min(int(round(cy0 * s)), s - n)
    img = img[oy : oy + n, ox : ox + n]
    img = resize(img, (size, size), order=1, anti_aliasing=True, mode="reflect")
    out = srgb_to_linear(img).astype(np.float32)
    out.setflags(write=False)
    return out
