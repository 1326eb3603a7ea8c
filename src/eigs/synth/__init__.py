"""Built-in synthetic scenes: independent NumPy ray caster with real textures, orbiting and shaking camera,
ESIM/v2e-style event simulator, exact ground truth, contact sheets, E²NeRF-layout export. See docs/synthetic.md.

Python API (imported lazily so ``eigs --help`` stays fast)::

    from eigs.synth import generate, write_generated, write_e2nerf_synthetic, SCENE_NAMES
    g = generate("toy", {"seed": 1})            # Generated: .scene, .params, .path, .stats, .blur_px
    write_generated(g, "scene.h5", contact_sheet="sheet.png")
    write_e2nerf_synthetic(g, "toy_e2nerf/")    # also accepts an eigs.scene.Scene read from a file
"""

from __future__ import annotations

from typing import Any

_LAZY = {
    "generate": "eigs.synth.generate",
    "write_generated": "eigs.synth.generate",
    "Generated": "eigs.synth.generate",
    "write_e2nerf_synthetic": "eigs.synth.export_e2nerf",
    "SCENE_NAMES": "eigs.synth.scenes",
    "DEFAULTS": "eigs.synth.scenes",
    "write_contact_sheet": "eigs.synth.contact_sheet",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'eigs.synth' has no attribute {name!r}")
