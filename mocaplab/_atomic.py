"""Writing files so that a reader sees the old file or the new one, never a piece.

Every file mocaplab writes (:func:`mocaplab.io.save_bvh`, the download cache
and the classroom mirror of :mod:`mocaplab.data`) goes through
:func:`atomic_write`:

1. the bytes go to a new temporary file in the destination's folder (so the
   final rename never crosses a file system), created with the permissions a
   plain ``open`` would give (or the existing file's, when one is replaced);
2. the file is flushed and ``fsync``-ed, so its bytes are on disk before its
   name is;
3. :func:`os.replace` puts it in place in one step, and the folder is synced
   (where the platform allows) so the new name survives a power cut.

When anything fails on the way (a full disk, a file-size limit, an exception
raised by the caller inside the ``with`` block, Ctrl-C), the temporary file is
removed and the destination is untouched: an existing file keeps its old
bytes, a missing one stays missing.  Only a process killed outright (SIGKILL,
a power cut) can leave a temporary file behind; its name starts with a dot
and ends with ``.tmp``, and the destination is still the old file or absent.

A symbolic link at the destination is followed: the file it points to is
replaced and the link is kept.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import stat
from collections.abc import Iterator
from typing import IO, Any, Literal

__all__ = ["atomic_write", "stale_temporaries", "TEMP_SUFFIX"]

#: Ending of the temporary files :func:`atomic_write` creates beside the destination.
TEMP_SUFFIX = ".tmp"
_TOKEN_BYTES = 6  # random bytes in a temporary file's name (12 hex digits)


def _prefix(name: str) -> str:
    """Start of the names of ``name``'s temporary files (cut so the whole name fits any file system)."""
    return f".{name[:200]}."


def stale_temporaries(path: str | os.PathLike[str]) -> list[str]:
    """Temporary files of ``path`` left by writers that were killed before they finished.

    A command that is run again to resume (``python -m mocaplab.data
    fetch``) removes them.  Two writers of the same file at the same time
    must not: each would see the other's file as stale.

    Parameters
    ----------
    path : str or path-like
        A destination of :func:`atomic_write`.

    Returns
    -------
    list of str
        Their paths (empty when the folder cannot be listed).
    """
    folder, name = os.path.split(os.path.realpath(os.fspath(path)))
    prefix = _prefix(name)
    try:
        entries = os.listdir(folder)
    except OSError:
        return []
    size = len(prefix) + 2 * _TOKEN_BYTES + len(TEMP_SUFFIX)
    return sorted(
        os.path.join(folder, e) for e in entries if len(e) == size and e.startswith(prefix) and e.endswith(TEMP_SUFFIX)
    )


def _sync_folder(folder: str) -> None:
    """Make a rename in ``folder`` durable (POSIX); a no-op where folders cannot be opened (Windows)."""
    try:
        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass  # some file systems refuse fsync on a folder; the rename itself is done
    finally:
        os.close(fd)


def _temporary(folder: str, name: str, mode: int | None) -> tuple[str, int]:
    """Create a new, empty temporary file beside ``name``; returns its path and an open descriptor."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_BINARY", 0)
    while True:
        # a name the caller cannot collide with (O_EXCL), short enough for any file system
        tmp = os.path.join(folder, f"{_prefix(name)}{secrets.token_hex(_TOKEN_BYTES)}{TEMP_SUFFIX}")
        try:
            fd = os.open(tmp, flags, 0o666)  # the umask applies, as for open(path, "w")
        except FileExistsError:
            continue
        break
    if mode is not None:
        try:
            os.fchmod(fd, mode)  # an existing file keeps its permissions
        except (AttributeError, OSError):
            pass  # no fchmod (Windows) or not allowed: the new file keeps the default permissions
    return tmp, fd


@contextlib.contextmanager
def atomic_write(
    path: str | os.PathLike[str],
    *,
    mode: Literal["wb", "w"] = "wb",
    encoding: str | None = None,
    newline: str | None = None,
) -> Iterator[IO[Any]]:
    """Open a temporary file that replaces ``path`` when the ``with`` block ends without an error.

    Parameters
    ----------
    path : str or path-like
        The destination.  Its folder must exist.  A symbolic link is followed.
    mode : {"wb", "w"}
        Binary (default) or text.
    encoding, newline : str, optional
        For text mode, as in :func:`open`.

    Yields
    ------
    file object
        Write the whole content to it.  Raise inside the block to abandon the
        write (for example when a check of the written bytes fails): the
        temporary file is removed and ``path`` is left as it was.

    Raises
    ------
    IsADirectoryError
        When ``path`` is a folder.
    OSError
        When the temporary file cannot be created, written, synced or renamed
        (a missing folder, no permission, a full disk); ``path`` is untouched.

    Examples
    --------
    >>> with atomic_write("notes.txt", mode="w", encoding="utf-8") as fh:  # doctest: +SKIP
    ...     fh.write("all or nothing\\n")
    """
    if mode not in ("wb", "w"):
        raise ValueError(f"Expected `mode` 'wb' or 'w', got {mode!r}")
    target = os.path.realpath(os.fspath(path))  # through symbolic links: the link stays, its file is replaced
    folder, name = os.path.split(target)
    existing: int | None = None
    try:
        st = os.stat(target)
    except FileNotFoundError:
        pass
    else:
        if stat.S_ISDIR(st.st_mode):
            raise IsADirectoryError(21, "Is a directory: cannot write a file over it", os.fspath(path))
        if stat.S_ISREG(st.st_mode):
            existing = stat.S_IMODE(st.st_mode)
    try:
        tmp, fd = _temporary(folder, name, existing)
    except OSError as exc:  # name the destination, not the temporary file
        raise type(exc)(exc.errno, exc.strerror, os.fspath(path)) from exc
    try:
        fh = os.fdopen(fd, mode, encoding=encoding, newline=newline)
    except BaseException:
        os.close(fd)
        os.unlink(tmp)
        raise
    try:
        yield fh
        fh.flush()
        os.fsync(fh.fileno())
        fh.close()
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            fh.close()  # closes the descriptor even when the final flush fails
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    _sync_folder(folder)
