"""Contact sheet of a scene: blurry frames, sharp ground truth, event-count images, novel views (one PNG).

Images are shown through an sRGB display transform (linear frames would look dark); the event row shows each
view's net signed event count over its exposure (red: ON, blue: OFF, white: none; saturated at ±8 events).
"""

from __future__ import annotations

import os
from collections.abc import Callable

import numpy as np

from eigs.scene import Events, Scene
from eigs.synth.response import decode
from eigs.util.image import linear_to_srgb, to_uint8, write_png

EVENT_SATURATION = 8.0


def _display(img_u8: np.ndarray, response: str) -> np.ndarray:
    lin = decode(img_u8, response)
    out = linear_to_srgb(lin) if response != "srgb" else np.asarray(img_u8) / 255.0
    if out.shape[-1] == 1:
        out = np.repeat(out, 3, axis=-1)
    return to_uint8(out)


def event_image(x: np.ndarray, y: np.ndarray, p: np.ndarray, width: int, height: int) -> np.ndarray:
    """(H, W, 3) uint8 RGB picture of the net signed count per pixel of events (x, y, p)."""
    net = np.zeros(height * width, np.float64)
    np.add.at(net, y.astype(np.int64) * width + x.astype(np.int64), p.astype(np.float64))
    a = np.clip(net / EVENT_SATURATION, -1, 1).reshape(height, width)
    img = np.ones((height, width, 3))
    pos, neg = np.clip(a, 0, 1), np.clip(-a, 0, 1)
    img[..., 1] -= pos + neg
    img[..., 2] -= pos
    img[..., 0] -= neg
    return to_uint8(img)


def _pick(n: int, k: int) -> list[int]:
    return sorted(set(np.linspace(0, n - 1, min(n, k)).round().astype(int).tolist())) if n > 0 else []


def contact_sheet(
    scene: Scene,
    *,
    max_columns: int = 8,
    min_tile_width: int = 128,
    view_events: Callable[[int], Events] | None = None,
) -> np.ndarray:
    """(H', W', 3) uint8 RGB contact sheet of ``scene`` (rows: blurry, sharp GT at the first latent time, events,
    novel views; whichever exist). ``view_events(v)``: view v's exposure events, for a scene whose events are not
    in memory (default: sliced from ``scene.events`` by its view index)."""
    import cv2

    w, h = scene.camera.width, scene.camera.height
    scale = max(1, int(np.ceil(min_tile_width / w)))
    rows: list[tuple[str, list[np.ndarray]]] = []
    n = scene.n_views
    cols = _pick(n, max_columns)
    resp = scene.camera_response
    if scene.frames is not None:
        rows.append(("blurry", [_display(scene.frames.blurry[v], resp) for v in cols]))
    sh = scene.sharp
    if sh is not None:
        blur_gt = {int(v): i for i, v in enumerate(sh.view) if sh.kind[i] == 0}
        tiles = [_display(sh.images[blur_gt[v]], resp) for v in cols if v in blur_gt]
        if tiles:
            rows.append(("sharp t0", tiles))
    ev = scene.events
    if view_events is None and ev is not None and ev.view_index is not None:
        view_events = ev.view
    if view_events is not None:
        tiles = []
        for v in cols:
            e = view_events(v)
            tiles.append(event_image(e.x, e.y, e.p, w, h))
        rows.append(("events", tiles))
    if sh is not None:
        novel = np.flatnonzero(sh.kind == 1)
        if novel.size:
            rows.append(("novel", [_display(sh.images[i], resp) for i in novel[_pick(novel.size, max_columns)]]))
    if not rows:
        rows.append(("empty", [np.zeros((h, w, 3), np.uint8)]))
    label_w, pad = 96, 4
    tw, th = w * scale, h * scale
    ncol = max(len(t) for _, t in rows)
    sheet = np.full((pad + len(rows) * (th + pad), label_w + ncol * (tw + pad), 3), 255, np.uint8)
    for r, (label, tiles) in enumerate(rows):
        y0 = pad + r * (th + pad)
        cv2.putText(sheet, label, (4, y0 + th // 2), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
        for c, tile in enumerate(tiles):
            x0 = label_w + c * (tw + pad)
            sheet[y0 : y0 + th, x0 : x0 + tw] = np.repeat(np.repeat(tile, scale, axis=0), scale, axis=1)
    return sheet


def write_contact_sheet(scene: Scene, path: str | os.PathLike, **kw) -> None:
    """Write :func:`contact_sheet` as a PNG (atomically)."""
    write_png(path, contact_sheet(scene, **kw))
