"""The one exception type for motion files that cannot be read.

:class:`MocapFormatError` (a ``ValueError``) is raised for every problem with
a file given to a reader, whether it lies in the file's bytes (a malformed
line, a truncated file, binary data) or in the path itself: a missing file, a
dangling symbolic link, a symbolic-link loop, an empty path, a directory, a
device or pipe, or a file that may not be read.  Either way the message names
the path, and the line when there is one.
"""

from __future__ import annotations

import os
from os import PathLike

__all__ = ["MocapFormatError"]


class MocapFormatError(ValueError):
    """A motion file could not be read.

    The message always names the file, the line (1-based; 0 when the problem
    concerns the whole file or its path) and what was expected versus what
    was found.  An empty path is shown as ``''``.

    Parameters
    ----------
    path : str, bytes or os.PathLike
        The file (kept as :attr:`path`, a str).
    line : int
        1-based line number; 0 for the whole file or its path.
    expected : str
        What the reader expected there.
    got : str, optional
        What it found (left out of the message when None).

    Examples
    --------
    >>> str(MocapFormatError("walk.bvh", 3, "'ROOT'", "'JOINT'"))
    "walk.bvh, line 3: expected 'ROOT', got 'JOINT'"
    """

    def __init__(self, path: str | PathLike[str], line: int, expected: str, got: str | None = None):
        self.path = os.fsdecode(path) if isinstance(path, bytes) else str(path)
        self.line = int(line)
        self.expected = expected
        self.got = got
        shown = self.path if self.path else "''"
        where = f"{shown}, line {self.line}" if self.line > 0 else shown
        msg = f"{where}: expected {expected}"
        if got is not None:
            msg += f", got {got}"
        super().__init__(msg)
