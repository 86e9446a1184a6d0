"""The one exception type for malformed motion files."""

from __future__ import annotations

from os import PathLike

__all__ = ["MocapFormatError"]


class MocapFormatError(ValueError):
    """A motion file could not be read.

    The message always names the file, the line (1-based; 0 when the problem
    concerns the whole file) and what was expected versus what was found.

    Attributes
    ----------
    path : str
    line : int
    expected : str
    """

    def __init__(self, path: str | PathLike[str], line: int, expected: str, got: str | None = None):
        self.path = str(path)
        self.line = int(line)
        self.expected = expected
        self.got = got
        where = f"{self.path}, line {self.line}" if self.line > 0 else self.path
        msg = f"{where}: expected {expected}"
        if got is not None:
            msg += f", got {got}"
        super().__init__(msg)
