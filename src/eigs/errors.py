"""The one exception type for user-facing errors.

Every error a user can cause (bad input file, missing artifact, bad option) is an ``EigsError`` whose
message names the file and the problem. The CLI prints it on one line, without a traceback, and exits 2.
"""

from __future__ import annotations

from os import PathLike


class EigsError(Exception):
    """A user-facing error: ``EigsError(path, problem)`` renders as ``"<path>: <problem>"``."""

    def __init__(self, path: str | PathLike | None, problem: str):
        self.path = None if path is None else str(path)
        self.problem = problem
        super().__init__(problem if self.path is None else f"{self.path}: {problem}")


# What h5py raises when it reads a damaged file: OSError (unreadable data), KeyError (an object it cannot resolve),
# RuntimeError (bad heap or B-tree signatures), ValueError/TypeError (a damaged datatype or a value of the wrong
# kind). Readers of HDF5 files catch these around their reads and raise EigsError naming the file.
H5_READ_ERRORS: tuple[type[Exception], ...] = (OSError, KeyError, RuntimeError, ValueError, TypeError)
