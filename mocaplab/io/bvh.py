"""Biovision Hierarchy (BVH) files.

Reading
-------
* Any per-joint channel order, rotation channels in any order (applied as
  intrinsic rotations in the order written: ``Zrotation Yrotation Xrotation``
  means ``R = Rz @ Ry @ Rx``), position channels on any joint, ``End Site``
  blocks, tabs, CRLF line endings and any float notation.
* A root with position channels is placed at the channel values (the root
  OFFSET, usually zero, is not added); components without a channel take the
  OFFSET.  Position channels on other joints replace that joint's OFFSET per
  frame (:attr:`Motion.translations`).
* BVH carries no unit.  ``scale`` is metres per file unit.  When it is not
  given, the unit is *estimated*: the rest pose (all rotations zero) is
  measured and, among metres, centimetres, millimetres, inches and the CMU
  Acclaim unit (1/0.45 inch), the unit that makes the figure closest to
  1.7 m tall (in ratio) is chosen, with a :class:`UserWarning` naming it.

Every problem raises :class:`~mocaplab.io.MocapFormatError` with the file
name, the line and what was expected; no partial Motion is ever returned.
Numbers are plain ASCII decimals or exponent floats (``1e-5``, ``+2.5E3``);
``nan``/``inf``, digit separators and non-ASCII digits are rejected.  LF,
CRLF and CR line endings and a UTF-8 byte-order mark are accepted; blank
(or whitespace-only) lines anywhere are skipped: in the hierarchy, between
``MOTION``, ``Frames:`` and ``Frame Time:`` (Perception Neuron writes one
after ``MOTION``) and between frame rows; spaces and tabs around any token
do not matter.  The text is UTF-8; a byte that is not (a Latin-1 accent in a
joint name) is read as Latin-1 with a warning naming its line
(:func:`decode_text`).

Paths and limits
----------------
* **Paths.** ``path`` is a ``str`` or ``os.PathLike``; a ``bytes`` path is
  decoded with :func:`os.fsdecode` (anything else is a ``TypeError``).  Every
  problem with the path itself is a :class:`~mocaplab.io.MocapFormatError`
  (a ``ValueError``) naming the path, at line 0: a missing file, a dangling
  symbolic link, a symbolic-link loop, an empty path, a directory, a device,
  pipe or socket (never read, so a FIFO cannot block), or a file that may not
  be read.  No ``OSError`` escapes a reader.
* **Memory is bounded by the file.** The ``Frames:`` count is checked against
  the rows actually present before anything is allocated: a header promising
  more rows than the file holds is the "truncated file" error.  Integers in
  headers (``CHANNELS`` and ``Frames:`` counts) longer than
  :data:`MAX_INTEGER_DIGITS` digits are rejected before conversion.
* **Frame rate.** ``1 / Frame Time`` must lie in :data:`FPS_RANGE`, 0.1 to
  10,000 frames per second (``Frame Time`` from 0.0001 s to 10 s), otherwise
  the file is rejected at its ``Frame Time`` line: rates outside it are typing
  errors, and would fail far from the file (a division by zero, a
  billion-frame resampling).

Speed: the frame rows are read by numpy's C reader in one call and checked
afterwards (row by row only when something is wrong, to name the line), and
the rotations are built in the component-major layout forward kinematics
uses, so reading CMU 49_03 (1504 frames) and computing its joint positions
takes a few times less than pure-Python readers (``benchmarks/bench_io.py``).

Longer than 800 lines because the reader and the writer share one grammar, its error positions (file, line, what was expected), the channel-order conventions and the memory bounds of a hostile file.
"""

from __future__ import annotations

import codecs
import errno
import math
import os
import re
import stat
import unicodedata
from collections.abc import Iterator
from dataclasses import dataclass, field
from os import PathLike

import numpy as np
from numpy.typing import NDArray

from .. import quat
from .._atomic import atomic_write
from .._warnings import warn
from ..motion import FPS_RANGE as MOTION_FPS_RANGE
from ..motion import VALID_CHANNELS, Motion, Skeleton, _Fresh, _owned
from . import euler
from ._hierarchy import check_reach
from .errors import MocapFormatError

__all__ = [
    "load_bvh",
    "save_bvh",
    "parse_bvh",
    "estimate_scale",
    "CANDIDATE_UNITS",
    "FPS_RANGE",
    "MAX_INTEGER_DIGITS",
    "MAX_INDENT",
]

#: Units considered by :func:`estimate_scale`, metres per unit.
CANDIDATE_UNITS: dict[str, float] = {
    "metres": 1.0,
    "centimetres": 0.01,
    "millimetres": 0.001,
    "inches": 0.0254,
    "CMU Acclaim units (1/0.45 inch)": 0.0254 / 0.45,
}
TYPICAL_HEIGHT_M = 1.7

#: Frame rates (frames per second, inclusive) that a file may declare; the
#: readers reject others (BVH at its ``Frame Time`` line, ``load_asf_amc``'s
#: ``fps`` argument) and :func:`save_bvh` does not write them.
FPS_RANGE = MOTION_FPS_RANGE

#: Most digits read for a header integer (a CHANNELS or Frames: count, an AMC
#: frame number): longer ones are rejected before ``int()`` sees them.
MAX_INTEGER_DIGITS = 18

#: Deepest indentation :func:`save_bvh` writes, in tabs: joints deeper in the
#: hierarchy are indented like this depth, so a line never grows with depth.
MAX_INDENT = 24


@dataclass
class _Joint:
    name: str
    parent: int
    offset: list[float]
    channels: tuple[str, ...] = ()
    line: int = 0
    end_sites: list[list[float]] = field(default_factory=list)


def _to_float(tok: str) -> float | None:
    """``float(tok)`` for plain ASCII number tokens, else None.

    Python's ``float`` also accepts digit separators (``1_000``) and non-ASCII
    digits, which no motion file means; numpy's reader rejects them too.
    """
    if not tok.isascii() or "_" in tok:
        return None
    try:
        return float(tok)
    except ValueError:
        return None


#: A token: a run of characters that are not whitespace (as ``str.split`` splits).
_TOKEN = re.compile(r"\S+")


class _Tokens:
    """Whitespace tokens of the hierarchy section with their line numbers."""

    def __init__(self, path: str, lines: list[str], stop: int):
        self.path = path
        self.lines = lines
        self.items: list[tuple[str, int]] = []
        self.columns: list[int] = []  # where each token starts on its line
        for number, text in enumerate(lines[:stop], start=1):
            for found in _TOKEN.finditer(text):
                self.items.append((found.group(), number))
                self.columns.append(found.start())
        self.pos = 0
        self.last_line = max(stop, 1)
        # what ends the tokens: the MOTION line, or the end of the file
        self.end = "'MOTION' (is a '}' missing?)" if stop < len(lines) else "end of file (truncated file?)"

    def written(self, first: int, stop: int) -> str | None:
        """The text of tokens ``first`` to ``stop - 1`` as written (inner whitespace kept), None if on several lines."""
        line = self.items[first][1]
        if self.items[stop - 1][1] != line:
            return None
        text = self.lines[line - 1]
        return text[self.columns[first] : self.columns[stop - 1] + len(self.items[stop - 1][0])]

    def peek(self) -> tuple[str, int] | None:
        return self.items[self.pos] if self.pos < len(self.items) else None

    def next(self, expected: str) -> tuple[str, int]:
        if self.pos >= len(self.items):
            line = self.last_line + 1 if self.end.startswith("'MOTION'") else self.last_line
            raise MocapFormatError(self.path, line, expected, self.end)
        item = self.items[self.pos]
        self.pos += 1
        return item

    def expect(self, word: str) -> int:
        tok, line = self.next(repr(word))
        if tok != word:
            raise MocapFormatError(self.path, line, repr(word), repr(tok[:40]))
        return line

    def number(self, where: str) -> float:
        tok, line = self.next(f"a number in {where}")
        value = _to_float(tok)
        if value is None:
            raise MocapFormatError(self.path, line, f"a number in {where}", repr(tok[:40]))
        if not math.isfinite(value):
            raise MocapFormatError(self.path, line, f"a finite number in {where}", repr(tok[:40]))
        return value


def as_path(path: object, argument: str = "path") -> str:
    """``path`` as a ``str``: ``str`` and ``os.PathLike`` as given, ``bytes`` decoded with :func:`os.fsdecode`.

    Raises
    ------
    TypeError
        For anything else, naming ``argument``.
    """
    try:
        value = os.fspath(path)  # type: ignore[call-overload]
    except TypeError:
        raise TypeError(f"Expected `{argument}` to be a str or os.PathLike, got {type(path).__name__}") from None
    return os.fsdecode(value) if isinstance(value, bytes) else value


def _path_problem(path: str, exc: OSError) -> str:
    """What is wrong with ``path``, for the ``got`` part of an error."""
    if exc.errno == getattr(errno, "ELOOP", None):
        return "a symbolic link loop"
    if isinstance(exc, IsADirectoryError) or os.path.isdir(path):
        return "a directory"
    if isinstance(exc, FileNotFoundError):
        if os.path.islink(path):
            try:
                target = os.readlink(path)
            except OSError:  # pragma: no cover - the link vanished meanwhile
                return "a dangling symbolic link"
            return f"a dangling symbolic link (to {target!r})"
        return "no such file"
    if isinstance(exc, NotADirectoryError):
        return "no such file (a folder in the path is a file)"
    if isinstance(exc, PermissionError):
        return "a file it may not read (permission denied)"
    return f"an unreadable path ({exc.strerror or exc})"


def read_bytes(path: str, what: str = "a text file") -> bytes:
    """The bytes of a regular file, or MocapFormatError naming ``path`` for any path problem.

    Missing files, dangling links, link loops, empty paths, directories,
    devices, pipes and sockets (opened without blocking and never read) and
    unreadable files all raise :class:`MocapFormatError` at line 0.
    """
    if not path:
        raise MocapFormatError(path, 0, f"a path to {what}", "an empty path")
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0)
    try:
        fd = os.open(path, flags)
    except OSError as exc:
        raise MocapFormatError(path, 0, what, _path_problem(path, exc)) from exc
    except ValueError:  # an embedded NUL character
        raise MocapFormatError(path, 0, f"a path to {what}", "a path with a NUL character") from None
    try:
        mode = os.fstat(fd).st_mode
    except OSError:  # pragma: no cover - fstat of an open descriptor
        mode = 0
    if not stat.S_ISREG(mode):
        os.close(fd)
        kind = "a directory" if stat.S_ISDIR(mode) else "not a regular file (a device, pipe or socket)"
        raise MocapFormatError(path, 0, what, kind)
    with open(fd, "rb") as fh:
        try:
            return fh.read()
        except OSError as exc:  # pragma: no cover - I/O errors of the disk
            raise MocapFormatError(path, 0, what, f"a read error ({exc.strerror or exc})") from exc


def read_text(path: str, what: str = "a text file") -> str:
    """The text of a motion file, or MocapFormatError for path problems, binary or undecodable bytes.

    A UTF-8 byte-order mark is dropped.  Line numbers in errors count ``\n``.
    """
    return decode_text(path, read_bytes(path, what))


def decode_text(path: str, raw: bytes) -> str:
    """``raw`` as text, or MocapFormatError (naming ``path``) for binary data.

    UTF-8 (with or without a byte-order mark) is the encoding.  A byte that is
    not part of valid UTF-8 (a Latin-1 ``\xe9`` in a comment or a joint name,
    as older Windows tools write) is read as the Latin-1 character of that
    byte, with a :class:`UserWarning` naming the line and the byte; valid
    UTF-8 around it is kept as UTF-8.  A NUL byte means binary data: error.
    """
    if b"\x00" in raw:
        line = raw[: raw.index(b"\x00")].count(b"\n") + 1
        raise MocapFormatError(path, line, "text", "binary data (NUL byte)")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        first = exc.start
    bom = len(codecs.BOM_UTF8) if raw.startswith(codecs.BOM_UTF8) else 0
    # surrogateescape maps each byte b >= 0x80 that is not UTF-8 to U+DC00 + b: turn it into Latin-1 chr(b)
    escaped = raw[bom:].decode("utf-8", "surrogateescape")
    n_bad = len(_ESCAPED.findall(escaped))
    text = escaped.translate(_ESCAPED_TO_LATIN1)
    line = raw[:first].count(b"\n") + 1
    start = raw.rfind(b"\n", 0, first) + 1
    stop = raw.find(b"\n", first)
    shown = raw[start : stop if stop >= 0 else len(raw)].decode("latin-1").strip()
    more = f" ({n_bad - 1} more such byte(s) read the same way)" if n_bad > 1 else ""
    warn(
        f"{path}, line {line}: byte 0x{raw[first]:02x} is not UTF-8; read as the Latin-1 character "
        f"{chr(raw[first])!r} (the line reads {shown[:60]!r}){more}. Save the file as UTF-8 to silence this",
        UserWarning,
    )
    return text


#: ``str.translate`` table from surrogate-escaped bytes (U+DC80-U+DCFF) to their Latin-1 characters.
_ESCAPED_TO_LATIN1 = {0xDC00 + b: b for b in range(0x80, 0x100)}
_ESCAPED = re.compile("[\udc80-\udcff]")


_read_text = read_text  # former private name


def split_lines(text: str) -> list[str]:
    """Lines of ``text`` for LF, CRLF or CR line endings (no other separators)."""
    if "\r" in text:
        text = text.replace("\r\n", "\n")
        if "\r" in text:
            text = text.replace("\r", "\n")
    return text.split("\n")


_KEYWORDS = ("{", "}", "OFFSET", "CHANNELS", "JOINT", "End", "ROOT")


def _parse_hierarchy(tok: _Tokens) -> list[_Joint]:
    """Joints in file order, from the tokens after ``HIERARCHY`` (no recursion)."""
    path = tok.path
    joints: list[_Joint] = []
    names: set[str] = set()
    t, line = tok.next("'ROOT'")
    if t != "ROOT":
        raise MocapFormatError(path, line, "'ROOT'", repr(t[:40]))
    # stack of open joints; a joint block is entered right after its keyword
    stack: list[int] = []
    keyword_line = line
    parent = -1
    while True:
        parts = []
        first = tok.pos
        while True:
            t, line = tok.next("a joint name followed by '{'")
            if t == "{":
                break
            if t in _KEYWORDS:
                raise MocapFormatError(path, line, "a joint name followed by '{'", repr(t))
            parts.append(t)
        if not parts:
            raise MocapFormatError(path, keyword_line, "a joint name", "none")
        # the name as written, checked with the writer's rules: what is read can be written back the same
        written = tok.written(first, first + len(parts))
        if written is None:
            raise MocapFormatError(path, keyword_line, "a joint name on one line", repr(" ".join(parts)[:60]))
        problem = _name_problem(written)
        if problem is not None:
            raise MocapFormatError(
                path, tok.items[first][1], "a joint name that a BVH file can hold (words of printable "
                "characters separated by single spaces, none a keyword)", f"{written[:60]!r}: {problem}",
            )
        name = written
        if name in names:
            raise MocapFormatError(path, keyword_line, "unique joint names", f"a second joint named {name!r}")
        names.add(name)
        tok.expect("OFFSET")
        offset = [tok.number("OFFSET") for _ in range(3)]
        joint = _Joint(name, parent, offset, line=keyword_line)
        joints.append(joint)
        stack.append(len(joints) - 1)
        nxt = tok.peek()
        if nxt is not None and nxt[0] == "CHANNELS":
            joint.channels = _parse_channels(tok)
        # children, end sites and closing braces until the next JOINT (or the end)
        while True:
            t, line = tok.next("'JOINT', 'End Site' or '}'")
            if t == "}":
                stack.pop()
                if not stack:
                    return joints
            elif t == "JOINT":
                keyword_line = line
                parent = stack[-1]
                break
            elif t == "End":
                tok.expect("Site")
                tok.expect("{")
                tok.expect("OFFSET")
                joints[stack[-1]].end_sites.append([tok.number("OFFSET") for _ in range(3)])
                tok.expect("}")
            else:
                raise MocapFormatError(path, line, "'JOINT', 'End Site' or '}'", repr(t[:40]))


def _parse_channels(tok: _Tokens) -> tuple[str, ...]:
    path = tok.path
    _, channels_line = tok.next("CHANNELS")
    t, line = tok.next("a channel count")
    if not (t.isascii() and t.isdigit()):
        raise MocapFormatError(path, line, "an integer channel count", repr(t[:40]))
    if len(t) > MAX_INTEGER_DIGITS:
        raise MocapFormatError(path, line, "a channel count between 0 and 6", f"a {len(t)}-digit number")
    count = int(t)
    if not 0 <= count <= 6:
        raise MocapFormatError(path, line, "a channel count between 0 and 6", str(count))
    names: list[str] = []
    for _ in range(count):
        c, cline = tok.next(f"{count} channel names")
        if c not in VALID_CHANNELS:
            if c in _KEYWORDS or _to_float(c) is not None:
                raise MocapFormatError(
                    path, channels_line, f"{count} channel names after 'CHANNELS {count}'", f"only {len(names)}"
                )
            raise MocapFormatError(path, cline, "a channel name (X/Y/Z position or rotation)", repr(c[:40]))
        if c in names:
            raise MocapFormatError(path, cline, "each channel once per joint", f"{c} twice")
        names.append(c)
    nxt = tok.peek()
    if nxt is not None and nxt[0] in VALID_CHANNELS:
        raise MocapFormatError(
            path, channels_line, f"{count} channel names after 'CHANNELS {count}'", f"more ({nxt[0]!r})"
        )
    return tuple(names)


#: The two header lines after MOTION; any whitespace around and inside the label.
_HEADER_LABELS = {"Frames:": re.compile(r"Frames\s*:"), "Frame Time:": re.compile(r"Frame\s+Time\s*:")}


def _line_at(text: str, pos: int) -> tuple[str, int]:
    """The line of ``text`` (newlines normalised) starting at ``pos`` and the position after it."""
    end = text.find("\n", pos)
    if end < 0:
        return text[pos:], len(text) + 1
    return text[pos:end], end + 1


def _header_value(path: str, text: str, pos: int, number: int, label: str, last: int) -> tuple[str, int, int]:
    """The value of header line ``label`` at the first line with text from ``pos`` (line ``number``).

    Returns the value, the number of that line and the position after it.
    Blank lines before it are skipped (Perception Neuron writes one after
    ``MOTION``); whitespace around and inside the label does not matter.
    ``last`` is the number of the file's last line with text.
    """
    while True:
        if pos > len(text) or number > last:
            raise MocapFormatError(path, last, f"'{label}' line", "end of file (truncated)")
        line, nxt = _line_at(text, pos)
        if line.strip():
            break
        pos, number = nxt, number + 1
    stripped = line.strip()
    match = _HEADER_LABELS[label].match(stripped)
    if match is None:
        raise MocapFormatError(path, number, f"'{label} <value>'", repr(stripped[:40]))
    return stripped[match.end():].strip(), number, nxt


def header_integer(text: str) -> int | None:
    """A header integer (plain ASCII digits, at most :data:`MAX_INTEGER_DIGITS`), else None."""
    if text.isascii() and text.isdigit() and len(text) <= MAX_INTEGER_DIGITS:
        return int(text)
    return None


def parse_bvh(path: str | bytes | PathLike[str]) -> tuple[list[_Joint], float, NDArray[np.float64]]:
    """Parse a BVH file into joints, frame time and the raw channel matrix (F, C).

    See the module notes for paths and limits.
    """
    path = as_path(path)
    return _parse_bvh_text(path, read_text(path, "a BVH file"))


def _parse_bvh_text(path: str, text: str) -> tuple[list[_Joint], float, NDArray[np.float64]]:
    """:func:`parse_bvh` of the file's text (``path`` names it in errors)."""
    joints, frame_time, rows = _parse_bvh_head(path, text)
    data = np.empty((rows.n_frames, rows.n_channels))
    for f0, block in rows.blocks():
        data[f0 : f0 + len(block)] = block
    return joints, frame_time, data


#: The ``MOTION`` line: the word alone on its line, whitespace around it.
_MOTION_LINE = re.compile(r"^[^\S\n]*MOTION[^\S\n]*$", re.MULTILINE)


def _end_of_text(text: str) -> int:
    """Position just after the last non-whitespace character of ``text`` (0 if none), without copying it."""
    end = len(text)
    while end > 0:
        tail = text[max(0, end - 4096) : end]
        kept = len(tail.rstrip())
        if kept:
            return end - len(tail) + kept
        end -= len(tail)
    return 0


def _parse_bvh_head(path: str, text: str) -> tuple[list[_Joint], float, _FrameRows]:
    """Joints, frame time and the (counted, not yet parsed) frame rows of a BVH text.

    Only the hierarchy is split into lines; the frame rows are read later in
    blocks (:class:`_FrameRows`), so reading holds the text, the result and
    one block, never a line object per frame or a full table of floats.
    """
    if "\r" in text:
        text = text.replace("\r\n", "\n")
        if "\r" in text:
            text = text.replace("\r", "\n")
    end = _end_of_text(text)
    if end == 0:
        raise MocapFormatError(path, 1, "'HIERARCHY'", "an empty file")
    last = text.count("\n", 0, end) + 1  # the last line with text
    pos, number = 0, 1
    while True:
        line, nxt = _line_at(text, pos)
        if line.strip():
            break
        pos, number = nxt, number + 1
    if line.strip() != "HIERARCHY":
        raise MocapFormatError(path, number, "'HIERARCHY'", repr(line.strip()[:40]))
    found = _MOTION_LINE.search(text, nxt, end)
    if found is None:
        lines = text[:end].split("\n")
        stop = len(lines)
    else:
        lines = text[: found.start()].split("\n")  # the hierarchy and an empty last item
        stop = len(lines) - 1
    tok = _Tokens(path, lines, stop)
    tok.pos = 1  # skip HIERARCHY
    joints = _parse_hierarchy(tok)
    extra = tok.peek()
    if extra is not None:
        if extra[0] == "}":
            raise MocapFormatError(path, extra[1], "'MOTION' after the hierarchy", "an unbalanced '}'")
        raise MocapFormatError(path, extra[1], "'MOTION' after the hierarchy", repr(extra[0][:40]))
    if found is None:
        raise MocapFormatError(path, last, "a 'MOTION' section", "end of file")
    del lines
    n_channels = sum(len(j.channels) for j in joints)
    if n_channels == 0:
        raise MocapFormatError(path, joints[0].line, "at least one CHANNELS entry in the hierarchy", "none")
    _, pos = _line_at(text, found.start())
    number = stop + 2
    frames_text, at, pos = _header_value(path, text, pos, number, "Frames:", last)
    n_frames = header_integer(frames_text)
    if n_frames is None:
        if frames_text.isascii() and frames_text.isdigit():
            raise MocapFormatError(
                path, at, f"a frame count of at most {MAX_INTEGER_DIGITS} digits", f"{len(frames_text)} digits"
            )
        raise MocapFormatError(path, at, "an integer frame count", repr(frames_text[:40]))
    if n_frames < 1:
        raise MocapFormatError(path, at, "a frame count of at least 1", str(n_frames))
    ft_text, at, pos = _header_value(path, text, pos, at + 1, "Frame Time:", last)
    frame_time = _to_float(ft_text)
    if frame_time is None:
        raise MocapFormatError(path, at, "a number of seconds per frame", repr(ft_text[:40]))
    if not (math.isfinite(frame_time) and frame_time > 0 and math.isfinite(1.0 / frame_time)):
        raise MocapFormatError(path, at, "a positive, finite Frame Time", ft_text[:40])
    if not FPS_RANGE[0] <= 1.0 / frame_time <= FPS_RANGE[1]:
        raise MocapFormatError(
            path, at, f"a Frame Time from {1 / FPS_RANGE[1]:g} to {1 / FPS_RANGE[0]:g} s "
            f"({FPS_RANGE[0]:g} to {FPS_RANGE[1]:g} frames per second)", f"{ft_text[:40]} ({1.0 / frame_time:.6g} fps)"
        )
    rows = _FrameRows(path, text, pos, at + 1, end, last, n_frames, n_channels)
    rows.check_count()
    return joints, frame_time, rows


#: Characters of frame rows read at a time (:class:`_FrameRows`): big enough
#: that numpy's reader runs at full speed, small beside any file worth
#: counting.
ROW_BLOCK_CHARS = 1 << 16


class _FrameRows:
    """The frame rows of a BVH text, read in blocks of about :data:`ROW_BLOCK_CHARS` characters.

    Blank (or whitespace-only) lines between rows are skipped.  Each block
    goes through numpy's C reader, which checks that every row has the same
    number of columns and every token is a number; a block it rejects is
    read again row by row to say exactly what is wrong and where.
    """

    def __init__(
        self, path: str, text: str, pos: int, number: int, end: int, last: int, n_frames: int, n_channels: int
    ):
        self.path, self.text, self.pos, self.number, self.end, self.last = path, text, pos, number, end, last
        self.n_frames, self.n_channels = n_frames, n_channels

    def _chunks(self) -> Iterator[tuple[list[str], int]]:
        """``(lines, number of the first)`` for consecutive blocks of whole lines."""
        text, pos, number, end = self.text, self.pos, self.number, self.end
        while pos < end:
            stop = text.find("\n", min(pos + ROW_BLOCK_CHARS, end))
            if stop < 0 or stop > end:
                stop = end
            lines = text[pos:stop].split("\n")
            yield lines, number
            number += len(lines)
            pos = stop + 1

    def check_count(self) -> None:
        """Raise if the file cannot hold the ``Frames:`` count of rows, before anything is allocated.

        A row holds ``C`` numbers and ``C - 1`` separators, so the rows
        present are at most the lines and at most ``(characters + 1) / 2C``:
        a count beyond that is read row by row for the first bad row, or the
        "truncated file" error.  Within it, the rows are counted as they are
        read (:meth:`blocks`).
        """
        text, pos, end = self.text, self.pos, self.end
        lines = text.count("\n", pos, end) + 1 if pos < end else 0
        if self.n_frames <= min(lines, (end - pos + 1) // (2 * self.n_channels)):
            return
        done = 0
        for chunk, number in self._chunks():  # the first bad row, in file order
            done += len(self._slow(chunk, number, done))
        self._truncated(done)

    def _truncated(self, done: int) -> None:
        raise MocapFormatError(
            self.path, self.last, f"{self.n_frames} frame row(s) as declared by 'Frames:'",
            f"{done} (truncated file?)",
        )

    def blocks(self) -> Iterator[tuple[int, NDArray[np.float64]]]:
        """``(first frame, values (k, C))`` for each block of rows, in order."""
        done = 0
        for lines, number in self._chunks():
            rows = lines if all(row and not row.isspace() for row in lines) else [
                row for row in lines if row and not row.isspace()
            ]
            if not rows:
                continue
            try:
                block = np.loadtxt(rows, dtype=np.float64, ndmin=2, comments=None)
            except ValueError:
                block = None
            if (
                block is None
                or block.shape != (len(rows), self.n_channels)
                or done + len(rows) > self.n_frames
                or not np.isfinite(block).all()
            ):
                block = self._slow(lines, number, done)
            yield done, block
            done += len(block)
        if done < self.n_frames:
            self._truncated(done)

    def _slow(self, lines: list[str], number: int, done: int) -> NDArray[np.float64]:
        """The rows of ``lines`` read one by one, or the error naming the first bad one."""
        path, n_frames, n_channels = self.path, self.n_frames, self.n_channels
        out: list[list[float | None]] = []
        for i, row in enumerate(lines):
            toks = row.split()
            if not toks:
                continue
            if done + len(out) >= n_frames:
                raise MocapFormatError(path, number + i, f"{n_frames} frame row(s) as declared by 'Frames:'", "more rows")
            if len(toks) != n_channels:
                raise MocapFormatError(
                    path, number + i, f"{n_channels} numbers in frame row {done + len(out) + 1}", f"{len(toks)}"
                )
            vals = [_to_float(x) for x in toks]
            for x, v in zip(toks, vals, strict=True):
                if v is None:
                    raise MocapFormatError(path, number + i, "a number", repr(x[:30]))
                if not math.isfinite(v):
                    raise MocapFormatError(path, number + i, "a finite number", repr(x[:30]))
            out.append(vals)
        return np.array(out, dtype=float).reshape(-1, n_channels)


def estimate_scale(skeleton_in_file_units: Skeleton) -> tuple[float, str]:
    """Guess metres per file unit from a skeleton's rest-pose size.

    Parameters
    ----------
    skeleton_in_file_units : Skeleton
        Offsets in the file's unit.

    Returns
    -------
    scale : float
        Metres per file unit, one of :data:`CANDIDATE_UNITS`.
    unit : str
        Its name.  A skeleton of zero (or non-finite) size gives ``(1.0, "metres")``.

    Notes
    -----
    The extent of the rest pose (all rotations zero; joints and end sites) is
    its largest side along x, y or z; the unit making that extent closest to
    1.7 m in ratio (``|log(extent * unit / 1.7)|`` smallest) wins.  A root
    with a single child and no end site is a reference joint (often placed
    at the origin while its child, the pelvis, sits at the first frame's
    world position): it is left out of the extent.

    Examples
    --------
    A figure 1.7 units tall is in metres, one 170 units tall in centimetres:

    >>> from mocaplab.motion import Skeleton
    >>> offsets = [[0, 95, 0], [0, 40, 0], [0, 35, 0], [10, -88, 0]]
    >>> sk = Skeleton(["hips", "spine", "head", "foot"], [-1, 0, 1, 0], offsets)
    >>> estimate_scale(sk)
    (0.01, 'centimetres')
    """
    sk = skeleton_in_file_units
    rest = Motion(sk, np.tile([0.0, 0.0, 0.0, 1.0], (1, sk.n_joints, 1)), sk.offsets[None, 0], 1.0)
    reference_root = sk.n_joints > 3 and int(np.sum(sk.parents == 0)) == 1 and not np.any(sk.end_site_parents == 0)
    with np.errstate(all="ignore"):
        joints = rest.global_positions()[0][1:] if reference_root else rest.global_positions()[0]
        pts = np.concatenate([joints, rest.end_site_positions()[0]])
        extent = float(np.max(np.ptp(pts, axis=0)))
    scores = {}
    for unit, metres in CANDIDATE_UNITS.items():
        size = extent * metres
        if math.isfinite(size) and size > 0:
            scores[unit] = abs(math.log(size / TYPICAL_HEIGHT_M))
    if not scores:
        return 1.0, "metres"
    best = min(scores, key=scores.__getitem__)
    return CANDIDATE_UNITS[best], best


_AXIS = {"X": 0, "Y": 1, "Z": 2}


def load_bvh(path: str | bytes | PathLike[str], *, scale: float | None = None, name: str | None = None) -> Motion:
    """Read a BVH file into a :class:`~mocaplab.motion.Motion`.

    Parameters
    ----------
    path : str or path-like
        A ``bytes`` path is decoded with :func:`os.fsdecode`.
    scale : float, optional
        Metres per file unit.  If omitted it is estimated (see
        :func:`estimate_scale`) and a ``UserWarning`` says which unit was
        assumed.
    name : str, optional
        Label for the motion (default: the file stem).

    Returns
    -------
    Motion
        Joints in file order with the file's names and channel orders, end
        sites, root positions from the root's position channels, local
        rotations from the rotation channels (``Motion.translations`` when a
        non-root joint has position channels), ``fps = 1 / Frame Time``.

    Raises
    ------
    MocapFormatError
        For any malformed file, naming the file, line and expectation, and
        for any problem with the path (missing, dangling link, link loop,
        empty, a directory, ...: see the module notes); a frame rate outside
        :data:`FPS_RANGE`.
    ValueError
        For a ``scale`` that is not a positive finite number.
    TypeError
        For a ``path`` that is not a str, bytes or os.PathLike.

    Examples
    --------
    A CMU clip from the mirror (``MOCAPLAB_DATA_DIR``), in CMU units of 1/0.45 inch:

    >>> from mocaplab.data import mirror_dir
    >>> walk = load_bvh(mirror_dir() / "bvh" / "16_15.bvh", scale=0.0254 / 0.45)
    >>> walk.name, walk.n_frames, round(walk.fps, 3), round(float(walk.root_positions[0, 1]), 3)
    ('16_15', 471, 120.0, 0.974)
    """
    path = as_path(path)
    _check_scale(scale)
    return _motion_from_text(path, read_text(path, "a BVH file"), scale=scale, name=name)


def check_scale(scale: object, what: str = "metres per file unit") -> None:
    """ValueError unless ``scale`` is None or a positive finite real number (not a bool or a string).

    The one check of the readers' ``scale`` option (BVH, ASF/AMC, FBX and :func:`~mocaplab.io.load`).
    """
    if scale is not None and not (
        isinstance(scale, (int, float, np.integer, np.floating))
        and not isinstance(scale, (bool, np.bool_))
        and math.isfinite(scale)  # type: ignore[arg-type]
        and scale > 0  # type: ignore[operator]
    ):
        raise ValueError(f"Expected `scale` > 0 ({what}), got {scale!r}")


_check_scale = check_scale


def load_bvh_bytes(raw: bytes, path: str, *, scale: float | None = None, name: str | None = None) -> Motion:
    """:func:`load_bvh` of a file's bytes already in memory (``path`` names it in errors and the default name).

    For callers that must parse exactly the bytes they checked (the data
    registry hashes a file, then parses those same bytes).
    """
    _check_scale(scale)
    return _motion_from_text(path, decode_text(path, raw), scale=scale, name=name)


def _motion_from_text(path: str, text: str, *, scale: float | None, name: str | None) -> Motion:
    joints, frame_time, rows = _parse_bvh_head(path, text)
    del text  # the rows keep what they need
    n = len(joints)
    offsets = np.array([j.offset for j in joints])
    esp = [i for i, j in enumerate(joints) for _ in j.end_sites]
    eso = [e for j in joints for e in j.end_sites]
    raw_skeleton = Skeleton(
        names=tuple(j.name for j in joints),
        parents=np.array([j.parent for j in joints], dtype=np.int64),
        offsets=offsets,
        channels=tuple(j.channels for j in joints),
        end_site_parents=np.array(esp, dtype=np.int64),
        end_site_offsets=np.array(eso, dtype=float).reshape(-1, 3),
    )
    if scale is None:
        scale, unit = estimate_scale(raw_skeleton)
        warn(
            f"{path}: BVH has no unit; assuming {unit} ({scale:g} m per unit) from the skeleton size. "
            "Pass scale=... to load_bvh to choose.",
            UserWarning,
        )
    scale = float(scale)
    n_frames = rows.n_frames
    # The results are filled block by block in memory that is then frozen
    # without a copy (motion._Fresh): reading holds the text, the results and
    # one block of rows.
    root_buf = _Fresh((n_frames, 3))
    root = root_buf.array
    root[:] = offsets[0]
    positions: list[tuple[int, int, int]] = []  # (column, joint, axis) of position channels
    groups: dict[str, list[tuple[int, list[int]]]] = {}
    col = 0
    for ji, j in enumerate(joints):
        rot_cols, order = [], ""
        for c in j.channels:
            if c[1] == "r":  # Xrotation, ...
                rot_cols.append(col)
                order += c[0]
            else:
                positions.append((col, ji, _AXIS[c[0]]))
            col += 1
        if order:
            groups.setdefault(order, []).append((ji, rot_cols))
    tr_buf = _Fresh((n_frames, n, 3)) if any(ji > 0 for _, ji, _ in positions) else None
    if tr_buf is not None:
        tr_buf.array[:] = offsets
    # Rotations are built component-major, (4, J, F): the layout forward
    # kinematics works in, so Motion.rotations is its (F, J, 4) transposed
    # view and no copy is made on the way.
    rot_buf = _Fresh((4, n, n_frames))
    rot4 = rot_buf.array
    if len(groups) != 1 or sum(len(m) for m in groups.values()) != n:
        rot4[:3] = 0.0
        rot4[3] = 1.0
    plans: list[tuple[str, list[int] | slice, list[NDArray[np.int64]]]] = []
    for order, members in groups.items():
        idx = [m[0] for m in members]
        cols = np.array([m[1] for m in members])  # (G, len(order))
        plans.append((order, idx if idx != list(range(n)) else slice(None), [cols[:, k] for k in range(len(order))]))
    for f0, block in rows.blocks():
        f1 = f0 + len(block)
        table = np.ascontiguousarray(block.T)  # (C, k): each channel contiguous
        del block
        for column, ji, axis in positions:
            if ji == 0:
                root[f0:f1, axis] = table[column]
            else:
                assert tr_buf is not None
                tr_buf.array[f0:f1, ji, axis] = table[column]
        for order, members_at, where in plans:
            quats = np.empty((4, len(where[0]), f1 - f0))
            euler.to_quat_channels(order, [table[w] for w in where], quats, degrees=True)
            rot4[:, members_at, f0:f1] = quats
    del rows
    translations = None if tr_buf is None else tr_buf.array
    with np.errstate(over="ignore"):  # overflow is reported below
        root *= scale
        if translations is not None:
            translations *= scale
        scaled_offsets = offsets * scale
        scaled_ends = raw_skeleton.end_site_offsets * scale
    big = [
        what
        for what, arr in (
            ("OFFSET", scaled_offsets),
            ("End Site OFFSET", scaled_ends),
            ("root position", root),
            ("joint position", translations),
        )
        if arr is not None and not np.isfinite(arr).all()
    ]
    if big:
        raise MocapFormatError(path, 0, f"{big[0]} values that stay finite in metres (scale {scale:g})", "an overflow")
    del root, translations, rot4
    skeleton = raw_skeleton.scaled(scale)
    motion = Motion(
        skeleton=skeleton,
        rotations=_owned(rot_buf.freeze().transpose(2, 1, 0)),
        root_positions=_owned(root_buf.freeze()),
        fps=1.0 / frame_time,
        translations=None if tr_buf is None else _owned(tr_buf.freeze()),
        name=name if name is not None else os.path.splitext(os.path.basename(path))[0],
    )
    check_reach(path, motion)
    return motion


def _dfs_order(parents: NDArray[np.int64]) -> list[int]:
    """Joints in depth-first order (children by index), the order BVH writes them."""
    children: list[list[int]] = [[] for _ in parents]
    for j in range(1, len(parents)):
        children[int(parents[j])].append(j)
    order: list[int] = []
    stack = [0]
    while stack:
        j = stack.pop()
        order.append(j)
        stack.extend(reversed(children[j]))
    return order


def _name_problem(name: str) -> str | None:
    """Why ``name`` cannot be written as a BVH joint name and read back the same, or None."""
    if not name:
        return "it is empty"
    try:
        name.encode("utf-8")
    except UnicodeEncodeError:
        return "it is not valid Unicode text (it holds a lone surrogate)"
    control = next((c for c in name if unicodedata.category(c) == "Cc"), None)
    if control is not None:
        return f"it holds the control character {control!r}"
    words = name.split()
    if " ".join(words) != name:
        return "it has leading, trailing or repeated whitespace, or whitespace other than a space"
    keyword = next((t for t in words if t in _KEYWORDS or t == "Site"), None)
    if keyword is not None:
        return f"its word {keyword!r} is a BVH keyword or brace"
    return None


def _writable_name(name: str) -> bool:
    return _name_problem(name) is None


def _length_decimals(largest: float, precision: int) -> int:
    """Decimals for lengths so that the largest one keeps at least ``precision + 1`` significant digits."""
    if not 0 < largest < 1:
        return precision
    return precision - math.floor(math.log10(largest))


def save_bvh(
    motion: Motion,
    path: str | bytes | PathLike[str],
    *,
    scale: float = 0.01,
    precision: int = 6,
    channels: list[tuple[str, ...]] | None = None,
) -> None:
    """Write a Motion as a BVH file that :func:`load_bvh` reads back.

    Parameters
    ----------
    motion : Motion
        Its ``fps`` must lie in :data:`FPS_RANGE` (what :func:`load_bvh` reads).
    path : str or path-like
        A ``bytes`` path is decoded with :func:`os.fsdecode`, as when reading.
    scale : float
        Metres per file unit (default 0.01: the file is in centimetres).
    precision : int
        Decimals written for every number (default 6, at most 17).  Lengths
        get more when the figure is small in file units: they keep at least
        ``precision + 1`` significant digits of the largest length written,
        so any ``scale`` whose file values stay finite reads back (a figure
        written with ``scale=1e300`` has lengths near ``1e-300`` units and is
        written with about 306 decimals rather than as zeros).
    channels : list of tuple of str, optional
        Channel order per joint; defaults to ``motion.skeleton.channels``.

    Notes
    -----
    * Joints are written depth first (children in index order), which is the
      order :func:`load_bvh` reads them back in; a skeleton built in another
      order (say breadth first) comes back reordered, with the same names.
    * A joint whose channels cannot hold its motion gets the channels it
      needs: three rotation channels (``Zrotation Yrotation Xrotation``) if
      it rotates but has fewer, and ``Xposition Yposition Zposition`` if its
      position (the root's path, or a non-root joint's animated translation)
      differs from its OFFSET on some axis without a channel.
    * Rotations are written as Euler angles in each joint's channel order
      (scipy), unwrapped over time so curves have no 360-degree jumps.
    * One tab of indentation per level of the hierarchy, up to
      :data:`MAX_INDENT` tabs: deeper joints are indented like that depth, so
      a 20,000-joint chain writes lines of bounded width (the reader ignores
      indentation).
    * Everything is checked and the whole text built before anything is
      written, and the text goes to a temporary file beside ``path`` that
      replaces it only once complete and synced to disk
      (:func:`mocaplab._atomic.atomic_write`): a failure (a full disk, an
      interruption) leaves an existing file unchanged and no partial file.

    Raises
    ------
    ValueError
        For a non-positive ``scale`` or one that overflows the lengths in
        file units, a ``precision`` that is not an integer from 0 to 17, bad
        ``channels``, a frame rate outside :data:`FPS_RANGE`, or a joint name
        that a BVH file cannot hold and give back: empty, not valid Unicode,
        with a control character (NUL, tab, newline, ...), leading, trailing
        or repeated whitespace or whitespace other than a space, or a BVH
        keyword or brace as a word (``{``, ``}``, ``JOINT``, ``End``, ...).
        The message names the joint.
    TypeError
        For a ``path`` that is not a str, bytes or os.PathLike.
    OSError
        When the file cannot be created or written.

    Examples
    --------
    Write a clip in centimetres and read it back:

    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mocaplab.data import cmu
    >>> walk = cmu("16_15")
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     save_bvh(walk, Path(folder) / "walk.bvh", scale=0.01)
    ...     back = load_bvh(Path(folder) / "walk.bvh", scale=0.01)
    >>> back.n_frames, bool(np.abs(back.global_positions() - walk.global_positions()).max() < 1e-6)
    (471, True)
    """
    if not isinstance(motion, Motion):
        hint = " (pass one of its `motions`, e.g. result.motions[0])" if hasattr(motion, "motions") else ""
        raise TypeError(f"Expected `motion` to be a Motion, got {type(motion).__name__}{hint}")
    path = as_path(path)
    if scale is None:
        raise ValueError(f"Expected `scale` > 0 (metres per file unit), got {scale!r}")
    check_scale(scale)
    if isinstance(precision, bool) or not isinstance(precision, (int, np.integer)) or not 0 <= precision <= 17:
        raise ValueError(f"Expected `precision` to be an integer from 0 to 17 (decimals), got {precision!r}")
    precision = int(precision)
    if not FPS_RANGE[0] <= motion.fps <= FPS_RANGE[1]:
        raise ValueError(
            f"Expected `motion.fps` from {FPS_RANGE[0]:g} to {FPS_RANGE[1]:g} frames per second "
            f"(the rates load_bvh reads), got {motion.fps!r}"
        )
    sk = motion.skeleton
    for j, joint_name in enumerate(sk.names):
        problem = _name_problem(joint_name)
        if problem is not None:
            raise ValueError(
                f"Joint {j} name {joint_name!r} cannot be written to a BVH file: {problem}; rename the joint"
            )
    chans = [tuple(c) for c in (channels if channels is not None else sk.channels)]
    if len(chans) != sk.n_joints:
        raise ValueError(f"Expected channels for {sk.n_joints} joints, got {len(chans)}")
    for j, c in enumerate(chans):
        if any(x not in VALID_CHANNELS for x in c) or len(set(c)) != len(c):
            raise ValueError(f"Invalid channels {c} for joint {sk.names[j]!r}")
    n_frames = motion.n_frames
    rot_needed = np.any(quat.angle(motion.rotations) > 1e-9, axis=0)
    for j in range(sk.n_joints):
        c = chans[j]
        if rot_needed[j] and sum(x[1] == "r" for x in c) < 3:
            c = tuple(x for x in c if x[1] == "p") + ("Zrotation", "Yrotation", "Xrotation")
        if j == 0:
            pos = motion.root_positions
        elif motion.translations is not None:
            pos = motion.translations[:, j]
        else:
            pos = None
        if pos is not None:
            have = {x[0] for x in c if x[1] == "p"}
            varies = [a for a, i in _AXIS.items() if np.any(pos[:, i] != sk.offsets[j, i])]
            if any(a not in have for a in varies):
                c = ("Xposition", "Yposition", "Zposition") + tuple(x for x in c if x[1] == "r")
        chans[j] = c
    order = _dfs_order(sk.parents)
    # Euler angles of all joints sharing a rotation order in one call
    # (fewer than three rotation channels only when the joint never rotates)
    by_order: dict[str, list[int]] = {}
    for j in order:
        rot_order = "".join(x[0] for x in chans[j] if x[1] == "r")
        if len(rot_order) == 3:
            by_order.setdefault(rot_order, []).append(j)
    euler_of: dict[int, NDArray[np.float64]] = {}
    for rot_order, members in by_order.items():
        angles = euler.from_quat(rot_order, motion.rotations[:, members])  # (F, G, 3)
        if n_frames > 1:
            angles = np.unwrap(angles, period=360.0, axis=0)
        euler_of.update((j, angles[:, g]) for g, j in enumerate(members))
    columns = []
    is_length: list[bool] = []
    with np.errstate(over="ignore"):  # overflow is reported below
        for j in order:
            c = chans[j]
            joint_angles = euler_of.get(j)
            if joint_angles is None:
                joint_angles = np.zeros((n_frames, 3))
            if j == 0:
                pos = motion.root_positions
            elif motion.translations is not None:
                pos = motion.translations[:, j]
            else:
                pos = np.broadcast_to(sk.offsets[j], (n_frames, 3))
            k = 0
            for x in c:
                if x[1] == "r":
                    columns.append(joint_angles[:, k])
                    is_length.append(False)
                    k += 1
                else:
                    columns.append(pos[:, _AXIS[x[0]]] / scale)
                    is_length.append(True)
        data = np.stack(columns, axis=1) if columns else np.zeros((n_frames, 0))
        offsets = sk.offsets / scale
        end_offsets = sk.end_site_offsets / scale
    lengths = np.concatenate([data[:, np.array(is_length, dtype=bool)].ravel(), offsets.ravel(), end_offsets.ravel()])
    largest = float(np.max(np.abs(lengths))) if lengths.size else 0.0
    if not math.isfinite(largest):
        raise ValueError(
            f"Expected `scale` to keep every length finite in file units, got {scale!r}: "
            "the motion's lengths divided by it overflow; pass a larger scale"
        )

    num = f"%.{precision}f"
    length_num = f"%.{_length_decimals(largest, precision)}f"
    out: list[str] = ["HIERARCHY"]
    children: list[list[int]] = [[] for _ in range(sk.n_joints)]
    for j in range(1, sk.n_joints):
        children[int(sk.parents[j])].append(j)
    ends: list[list[NDArray[np.float64]]] = [[] for _ in range(sk.n_joints)]
    for p, e in zip(sk.end_site_parents, end_offsets, strict=True):
        ends[int(p)].append(e)
    triple = f"{length_num} {length_num} {length_num}"
    # iterative depth-first writer: ("open", j, depth) or ("close", j, depth)
    stack: list[tuple[str, int, int]] = [("open", 0, 0)]
    while stack:
        what, j, depth = stack.pop()
        pad = "\t" * min(depth, MAX_INDENT)
        if what == "close":
            for e in ends[j]:
                out.append(f"{pad}\tEnd Site")
                out.append(pad + "\t{")
                out.append(f"{pad}\t\tOFFSET " + triple % tuple(e))
                out.append(pad + "\t}")
            out.append(pad + "}")
            continue
        out.append(f"{pad}{'ROOT' if j == 0 else 'JOINT'} {sk.names[j]}")
        out.append(pad + "{")
        out.append(f"{pad}\tOFFSET " + triple % tuple(offsets[j]))
        out.append(f"{pad}\tCHANNELS {len(chans[j])}" + "".join(" " + x for x in chans[j]))
        stack.append(("close", j, depth))
        stack.extend(("open", c, depth + 1) for c in reversed(children[j]))
    out.append("MOTION")
    out.append(f"Frames: {n_frames}")
    # 17 significant digits: reading back gives the same fps to the last bit
    out.append(f"Frame Time: {1.0 / motion.fps:.17g}")
    row = " ".join(length_num if length else num for length in is_length)
    out.extend(row % tuple(values) for values in data.tolist())
    text = "\n".join(out) + "\n"
    with atomic_write(path, mode="w", encoding="utf-8", newline="\n") as fh:
        fh.write(text)
