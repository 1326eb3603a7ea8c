"""Ingestion: event and frame sources → the scene file (``eigs ingest``).

One module per source format (:mod:`eigs.ingest.e2nerf`, :mod:`eigs.ingest.h5events`,
:mod:`eigs.ingest.text`, :mod:`eigs.ingest.aedat4`, …) plus shared pieces: :mod:`eigs.ingest.options` (user
options), :mod:`eigs.ingest.images`, :mod:`eigs.ingest.timeconv` (units, polarity), :mod:`eigs.ingest.poses`
(axis conventions), :mod:`eigs.ingest.undistort`, :mod:`eigs.ingest.raw` (time windows, view assignment,
streaming write) and :mod:`eigs.ingest.summary`.
Conventions and the exact conversions of every format: ``docs/ingestion.md``.

Kept import-light: the CLI imports this package at start-up.
"""

from __future__ import annotations

FORMATS = ("e2nerf-synthetic", "e2nerf-real", "h5", "txt", "aedat4", "rosbag", "prophesee", "aedat", "numpy")


def ingest(fmt: str, source: str, out: str, options: object | None = None) -> str:
    """Read ``source`` in format ``fmt`` and write the scene file ``out`` atomically.

    ``options``: an :class:`eigs.ingest.options.IngestOptions` (defaults when None). Returns the printed summary.
    Raises :class:`eigs.errors.EigsError` on bad input; nothing is written then.
    """
    from eigs.errors import EigsError
    from eigs.ingest.options import IngestOptions

    opts = options if options is not None else IngestOptions()
    assert isinstance(opts, IngestOptions)
    if fmt != "numpy":
        opts.refuse(fmt, "columns")
    if fmt != "rosbag":
        opts.refuse(fmt, "topics")
    if fmt in ("e2nerf-synthetic", "e2nerf-real"):
        from eigs.ingest.e2nerf import ingest_e2nerf

        return ingest_e2nerf(fmt, source, out, opts)
    if fmt == "h5":
        from eigs.ingest.h5events import open_h5_source as opener
    elif fmt == "txt":
        from eigs.ingest.text import open_text_source as opener
    elif fmt == "aedat4":
        from eigs.ingest.aedat4 import open_aedat4_source as opener
    elif fmt == "rosbag":
        from eigs.ingest.rosbag import open_rosbag_source as opener
    elif fmt == "prophesee":
        from eigs.ingest.prophesee import open_prophesee_source as opener
    elif fmt == "aedat":
        from eigs.ingest.aedat_legacy import open_aedat_legacy_source as opener
    elif fmt == "numpy":
        from eigs.ingest.numpy_events import open_numpy_source as opener
    else:
        raise EigsError(None, f"unknown format {fmt!r} (one of {', '.join(FORMATS)})")
    from eigs.ingest.raw import ingest_raw

    return ingest_raw(opener(source, opts), out, opts)
