"""Atomic file and directory writes: write to a temporary sibling, rename on success, delete on failure."""

from __future__ import annotations

import contextlib
import errno
import os
import re
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

from eigs.errors import EigsError

_RANDOM = r"[a-z0-9_]{8}"  # tempfile's random part of a name
# any target's temporary (the names :func:`temporary_pattern` matches for one target)
ANY_TEMPORARY = re.compile(rf"\..+\.{_RANDOM}\.tmp(\.[A-Za-z0-9]+)?")
FULL_BELOW = 1 << 20  # bytes: a filesystem with less free space than this counts as full
# How the writers report a full disk when they keep no errno: h5py's HDF5 error stack, pycolmap's SQLite, torch.save
_FULL_TEXT = ("no space left on device", "errno = 28", "database or disk is full", "file write failed")


def _existing(path: Path) -> Path:
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def free_bytes(path: str | os.PathLike) -> int | None:
    """Free bytes on the filesystem of ``path`` (its nearest existing ancestor); None when that cannot be read."""
    try:
        return shutil.disk_usage(_existing(Path(path))).free
    except OSError:
        return None


def is_disk_full(err: BaseException, path: str | os.PathLike | None = None) -> bool:
    """Whether ``err`` (or an exception it was raised from) is a write refused for want of space: ENOSPC or EDQUOT,
    the words writers use for it, or any OSError/RuntimeError while the filesystem of ``path`` has less than
    :data:`FULL_BELOW` bytes free (pycolmap's SQLite says only that it could not open its database)."""
    seen: set[int] = set()
    e: BaseException | None = err
    while e is not None and id(e) not in seen:
        seen.add(id(e))
        if isinstance(e, OSError) and e.errno in (errno.ENOSPC, errno.EDQUOT):
            return True
        if any(t in str(e).lower() for t in _FULL_TEXT):
            return True
        e = e.__cause__ or e.__context__
    if path is not None and isinstance(err, (OSError, RuntimeError)):
        free = free_bytes(path)
        return free is not None and free < FULL_BELOW
    return False


def ensure_space(target: str | os.PathLike, nbytes: int) -> None:
    """Refuse, as a full disk, a write of about ``nbytes`` into the filesystem of ``target`` that would not fit
    (2 % and :data:`FULL_BELOW` of headroom for the format's own structures). HDF5 writes call it first: h5py
    crashes the process (SIGSEGV in ``File.close``, h5py 3.16 / HDF5 1.14) when a write has failed for want of
    space, so that error must never reach it."""
    free = free_bytes(target)
    if free is not None and free < int(nbytes * 1.02) + FULL_BELOW:
        raise disk_full_error(target, free)


def nbytes_of(*values: object, _depth: int = 0) -> int:
    """Bytes of the arrays among ``values``, looking into dataclasses, lists, tuples and dicts (three levels deep);
    anything else counts 0."""
    import dataclasses

    total = 0
    for v in values:
        if hasattr(v, "nbytes") and hasattr(v, "dtype"):
            total += int(v.nbytes)
        elif _depth < 3 and dataclasses.is_dataclass(v) and not isinstance(v, type):
            total += nbytes_of(*(getattr(v, f.name) for f in dataclasses.fields(v)), _depth=_depth + 1)
        elif _depth < 3 and isinstance(v, (list, tuple)):
            total += nbytes_of(*v, _depth=_depth + 1)
        elif _depth < 3 and isinstance(v, dict):
            total += nbytes_of(*v.values(), _depth=_depth + 1)
    return total


class DiskFullError(EigsError):
    """A write refused for want of space, naming the artifact that was being written."""


def disk_full_error(path: str | os.PathLike, free: int | None) -> DiskFullError:
    """The one-line error of a write refused for want of space (``path``: the artifact being written)."""
    left = "" if free is None else f", {free:,} bytes free"
    return DiskFullError(path, f"no space left on its filesystem{left}: nothing was written; free space and rerun")


def temporary_pattern(path: Path, *, directory: bool = False) -> re.Pattern[str]:
    """The names :func:`atomic_path` gives the temporaries of ``path`` (a dot, the name, eight random characters and
    ``.tmp`` for a directory; a dot, the stem, eight random characters, ``.tmp`` and the suffix for a file), and no
    other target's."""
    if directory:
        return re.compile(rf"\.{re.escape(path.name)}\.{_RANDOM}\.tmp")
    return re.compile(rf"\.{re.escape(path.stem)}\.{_RANDOM}\.tmp{re.escape(path.suffix)}")


def remove_stale_temporaries(path: Path, *, directory: bool = False) -> list[Path]:
    """Delete what an earlier write of ``path`` that was killed (SIGKILL, power loss: no cleanup ran) left beside
    it; returns the removed paths. Only this target's temporaries match, and one target is written by one job at a
    time (Snakemake's lock), so none of them belongs to a live writer."""
    pattern = temporary_pattern(path, directory=directory)
    removed = []
    with contextlib.suppress(FileNotFoundError):
        for entry in os.scandir(path.parent):
            if pattern.fullmatch(entry.name):
                if entry.is_dir(follow_symlinks=False):
                    shutil.rmtree(entry.path, ignore_errors=True)
                else:
                    with contextlib.suppress(FileNotFoundError):
                        os.unlink(entry.path)
                removed.append(Path(entry.path))
    return removed


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, *, directory: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on normal exit rename it onto ``path``.

    If the block raises, the temporary file (or directory) is removed and ``path`` is left as it was,
    so a failed write never leaves a half-written artifact behind. The temporary name keeps the
    suffix of ``path`` so libraries that infer a format from the extension still work. A killed process runs no
    cleanup: the next write of ``path`` first removes the temporaries it left (:func:`remove_stale_temporaries`).
    A write refused for want of space becomes one :class:`eigs.errors.EigsError` naming ``path``
    (:func:`is_disk_full`), the temporary removed all the same.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(path, directory=directory)
    if directory:
        tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent))
    else:
        fd, name = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}", dir=path.parent)
        os.close(fd)
        tmp = Path(name)
        tmp.unlink()  # writers create the file themselves (h5py refuses some pre-existing files)
    try:
        yield tmp
        if directory:
            if path.exists():
                shutil.rmtree(path)
            os.replace(tmp, path)
        else:
            os.replace(tmp, path)
    except BaseException as err:
        # a full disk met by a write nested in this one (a file of a directory being written) names this artifact
        inner = isinstance(err, DiskFullError) and err.path is not None and Path(tmp) in Path(err.path).parents
        full = inner or (not isinstance(err, (EigsError, KeyboardInterrupt)) and is_disk_full(err, path))
        if tmp.is_dir():
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()
        if full:
            raise disk_full_error(path, free_bytes(path)) from err
        raise
