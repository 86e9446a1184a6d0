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
"""

from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass, field
from os import PathLike

import numpy as np
from numpy.typing import NDArray
from .. import quat
from ..motion import VALID_CHANNELS, Motion, Skeleton
from . import euler
from .errors import MocapFormatError

__all__ = ["load_bvh", "save_bvh", "parse_bvh", "estimate_scale", "CANDIDATE_UNITS"]

#: Units considered by :func:`estimate_scale`, metres per unit.
CANDIDATE_UNITS: dict[str, float] = {
    "metres": 1.0,
    "centimetres": 0.01,
    "millimetres": 0.001,
    "inches": 0.0254,
    "CMU Acclaim units (1/0.45 inch)": 0.0254 / 0.45,
}
TYPICAL_HEIGHT_M = 1.7


@dataclass
class _Joint:
    name: str
    parent: int
    offset: list[float]
    channels: tuple[str, ...] = ()
    line: int = 0
    end_sites: list[list[float]] = field(default_factory=list)


class _Tokens:
    """Whitespace tokens of the hierarchy section with their line numbers."""

    def __init__(self, path: str, lines: list[str], stop: int):
        self.path = path
        self.items: list[tuple[str, int]] = []
        for number, text in enumerate(lines[:stop], start=1):
            for tok in text.split():
                self.items.append((tok, number))
        self.pos = 0
        self.last_line = stop

    def peek(self) -> tuple[str, int] | None:
        return self.items[self.pos] if self.pos < len(self.items) else None

    def next(self, expected: str) -> tuple[str, int]:
        if self.pos >= len(self.items):
            raise MocapFormatError(self.path, self.last_line, expected, "end of the hierarchy")
        item = self.items[self.pos]
        self.pos += 1
        return item

    def expect(self, word: str) -> int:
        tok, line = self.next(repr(word))
        if tok != word:
            raise MocapFormatError(self.path, line, repr(word), repr(tok))
        return line

    def number(self, what: str) -> float:
        tok, line = self.next(what)
        try:
            value = float(tok)
        except ValueError:
            raise MocapFormatError(self.path, line, what, repr(tok)) from None
        if not math.isfinite(value):
            raise MocapFormatError(self.path, line, f"a finite {what}", repr(tok))
        return value


def _read_text(path: str) -> str:
    try:
        with open(path, "rb") as fh:
            raw = fh.read()
    except IsADirectoryError:
        raise MocapFormatError(path, 0, "a BVH file", "a directory") from None
    if b"\x00" in raw:
        line = raw[: raw.index(b"\x00")].count(b"\n") + 1
        raise MocapFormatError(path, line, "text", "binary data (NUL byte)")
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise MocapFormatError(path, line, "UTF-8 or ASCII text", f"undecodable byte 0x{raw[exc.start]:02x}") from None


def _parse_joint(tok: _Tokens, joints: list[_Joint], parent: int, keyword_line: int) -> None:
    path = tok.path
    parts = []
    while True:
        t, line = tok.next("a joint name followed by '{'")
        if t == "{":
            break
        if t in ("}", "OFFSET", "CHANNELS", "JOINT"):
            raise MocapFormatError(path, line, "a joint name followed by '{'", repr(t))
        parts.append(t)
    if not parts:
        raise MocapFormatError(path, keyword_line, "a joint name", "none")
    name = " ".join(parts)
    if any(j.name == name for j in joints):
        raise MocapFormatError(path, keyword_line, "unique joint names", f"a second joint named {name!r}")
    tok.expect("OFFSET")
    offset = [tok.number("an OFFSET number") for _ in range(3)]
    joint = _Joint(name, parent, offset, line=keyword_line)
    index = len(joints)
    joints.append(joint)
    nxt = tok.peek()
    if nxt is not None and nxt[0] == "CHANNELS":
        tok.next("CHANNELS")
        t, line = tok.next("a channel count")
        try:
            count = int(t)
        except ValueError:
            raise MocapFormatError(path, line, "an integer channel count", repr(t)) from None
        if not 0 <= count <= 6:
            raise MocapFormatError(path, line, "a channel count between 0 and 6", str(count))
        names = []
        for _ in range(count):
            c, cline = tok.next(f"{count} channel names")
            if c not in VALID_CHANNELS:
                if c in ("JOINT", "End", "}", "{") or c.lstrip("-").replace(".", "").isdigit():
                    raise MocapFormatError(
                        path, cline, f"{count} channel names after 'CHANNELS {count}'", f"only {len(names)}"
                    )
                raise MocapFormatError(
                    path, cline, "a channel name (X/Y/Z position or rotation)", repr(c)
                )
            if c in names:
                raise MocapFormatError(path, cline, "each channel once per joint", f"{c} twice")
            names.append(c)
        nxt = tok.peek()
        if nxt is not None and nxt[0] in VALID_CHANNELS:
            raise MocapFormatError(path, nxt[1], f"{count} channel names as declared", f"more ({nxt[0]!r})")
        joint.channels = tuple(names)
    while True:
        t, line = tok.next("'JOINT', 'End Site' or '}'")
        if t == "}":
            return
        if t == "JOINT":
            _parse_joint(tok, joints, index, line)
        elif t == "End":
            tok.expect("Site")
            tok.expect("{")
            tok.expect("OFFSET")
            joint.end_sites.append([tok.number("an OFFSET number") for _ in range(3)])
            tok.expect("}")
        else:
            raise MocapFormatError(path, line, "'JOINT', 'End Site' or '}'", repr(t))


def _header_value(path: str, lines: list[str], i: int, label: str) -> str:
    if i >= len(lines):
        raise MocapFormatError(path, i + 1, f"'{label}' line", "end of file (truncated)")
    text = lines[i].strip()
    if not text.startswith(label):
        raise MocapFormatError(path, i + 1, f"'{label} <value>'", repr(text[:40]))
    return text[len(label):].strip()


def parse_bvh(path: str | PathLike[str]) -> tuple[list[_Joint], float, NDArray[np.float64]]:
    """Parse a BVH file into joints, frame time and the raw channel matrix (F, C)."""
    path = os.fspath(path)
    text = _read_text(path)
    lines = text.splitlines()
    first = next((i for i, s in enumerate(lines) if s.strip()), None)
    if first is None:
        raise MocapFormatError(path, 1, "'HIERARCHY'", "an empty file")
    if lines[first].strip() != "HIERARCHY":
        raise MocapFormatError(path, first + 1, "'HIERARCHY'", repr(lines[first].strip()[:40]))
    motion_line = next((i for i in range(first + 1, len(lines)) if lines[i].strip() == "MOTION"), None)
    stop = motion_line if motion_line is not None else len(lines)
    tok = _Tokens(path, lines, stop)
    tok.pos = 1  # skip HIERARCHY
    joints: list[_Joint] = []
    t, line = tok.next("'ROOT'")
    if t != "ROOT":
        raise MocapFormatError(path, line, "'ROOT'", repr(t))
    _parse_joint(tok, joints, -1, line)
    extra = tok.peek()
    if extra is not None:
        if extra[0] == "}":
            raise MocapFormatError(path, extra[1], "'MOTION' after the hierarchy", "an unbalanced '}'")
        raise MocapFormatError(path, extra[1], "'MOTION' after the hierarchy", repr(extra[0]))
    if motion_line is None:
        raise MocapFormatError(path, len(lines), "a 'MOTION' section", "end of file")
    frames_text = _header_value(path, lines, motion_line + 1, "Frames:")
    try:
        n_frames = int(frames_text)
    except ValueError:
        raise MocapFormatError(path, motion_line + 2, "an integer frame count", repr(frames_text)) from None
    if n_frames < 1:
        raise MocapFormatError(path, motion_line + 2, "a frame count of at least 1", str(n_frames))
    ft_text = _header_value(path, lines, motion_line + 2, "Frame Time:")
    try:
        frame_time = float(ft_text)
    except ValueError:
        raise MocapFormatError(path, motion_line + 3, "a number of seconds per frame", repr(ft_text)) from None
    if not (math.isfinite(frame_time) and frame_time > 0):
        raise MocapFormatError(path, motion_line + 3, "a positive, finite Frame Time", ft_text)
    n_channels = sum(len(j.channels) for j in joints)
    data = _parse_rows(path, lines, motion_line + 3, n_frames, n_channels)
    return joints, frame_time, data


def _parse_rows(path: str, lines: list[str], start: int, n_frames: int, n_channels: int) -> NDArray[np.float64]:
    rows = lines[start:]
    while rows and not rows[-1].strip():
        rows.pop()
    # Fast path: numpy's C reader checks that every row has the same number of
    # columns and that every token is a number; anything it rejects is
    # re-read row by row below to say exactly what is wrong and where.
    if len(rows) == n_frames and n_channels > 0:
        try:
            flat = np.loadtxt(rows, dtype=np.float64, ndmin=2, comments=None)
        except ValueError:
            flat = None
        if flat is not None and flat.shape == (n_frames, n_channels) and np.all(np.isfinite(flat)):
            return flat
    # Slow path: row by row, to say exactly what is wrong and where.
    out = np.empty((n_frames, n_channels))
    count = 0
    for i, row in enumerate(rows):
        number = start + i + 1
        toks = row.split()
        if not toks:
            if count < n_frames:
                raise MocapFormatError(path, number, f"a frame row of {n_channels} numbers", "an empty line")
            continue
        if count >= n_frames:
            raise MocapFormatError(path, number, f"{n_frames} frame rows as declared by 'Frames:'", "more rows")
        if len(toks) != n_channels:
            raise MocapFormatError(path, number, f"{n_channels} numbers in frame row {count + 1}", f"{len(toks)}")
        try:
            vals = [float(x) for x in toks]
        except ValueError:
            bad = next(x for x in toks if not _is_float(x))
            raise MocapFormatError(path, number, "a number", repr(bad[:30])) from None
        arr = np.asarray(vals)
        if not np.all(np.isfinite(arr)):
            bad = toks[int(np.flatnonzero(~np.isfinite(arr))[0])]
            raise MocapFormatError(path, number, "a finite number", repr(bad))
        out[count] = arr
        count += 1
    if count < n_frames:
        raise MocapFormatError(
            path, start + len(rows), f"{n_frames} frame rows as declared by 'Frames:'", f"{count} (truncated file?)"
        )
    return out


def _is_float(x: str) -> bool:
    try:
        float(x)
    except ValueError:
        return False
    return True


def estimate_scale(skeleton_in_file_units: Skeleton) -> tuple[float, str]:
    """Guess metres per file unit from a skeleton's rest-pose size.

    Returns ``(scale, unit_name)``; see the module docstring for the rule.
    """
    sk = skeleton_in_file_units
    rest = Motion(sk, np.tile([0.0, 0.0, 0.0, 1.0], (1, sk.n_joints, 1)), sk.offsets[None, 0], 1.0)
    pts = np.concatenate([rest.global_positions()[0], rest.end_site_positions()[0]])
    extent = float(np.max(np.ptp(pts, axis=0)))
    if extent <= 0:
        return 1.0, "metres"
    best = min(CANDIDATE_UNITS.items(), key=lambda kv: abs(math.log(extent * kv[1] / TYPICAL_HEIGHT_M)))
    return best[1], best[0]


_AXIS = {"X": 0, "Y": 1, "Z": 2}


def load_bvh(path: str | PathLike[str], *, scale: float | None = None, name: str | None = None) -> Motion:
    """Read a BVH file into a :class:`~mocaplab.motion.Motion`.

    Parameters
    ----------
    path : str or path-like
    scale : float, optional
        Metres per file unit.  If omitted it is estimated (see module notes)
        and a ``UserWarning`` says which unit was assumed.
    name : str, optional
        Label for the motion (default: the file stem).

    Raises
    ------
    MocapFormatError
        For any malformed file, naming the file, line and expectation.
    """
    path = os.fspath(path)
    joints, frame_time, data = parse_bvh(path)
    n = len(joints)
    offsets = np.array([j.offset for j in joints])
    esp = [i for i, j in enumerate(joints) for _ in j.end_sites]
    eso = [e for j in joints for e in j.end_sites]
    raw_skeleton = Skeleton(
        names=[j.name for j in joints],
        parents=np.array([j.parent for j in joints], dtype=np.int64),
        offsets=offsets,
        channels=[j.channels for j in joints],
        end_site_parents=np.array(esp, dtype=np.int64),
        end_site_offsets=np.array(eso, dtype=float).reshape(-1, 3),
    )
    if scale is None:
        scale, unit = estimate_scale(raw_skeleton)
        warnings.warn(
            f"{path}: BVH has no unit; assuming {unit} ({scale:g} m per unit) from the skeleton size. "
            "Pass scale=... to load_bvh to choose.",
            UserWarning,
            stacklevel=2,
        )
    if not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"Expected `scale` > 0 (metres per file unit), got {scale!r}")
    n_frames = data.shape[0]
    rotations = np.empty((n_frames, n, 4))
    rotations[...] = (0.0, 0.0, 0.0, 1.0)
    root = np.broadcast_to(offsets[0], (n_frames, 3)).copy()
    translations = None
    groups: dict[str, list[tuple[int, list[int]]]] = {}
    col = 0
    for ji, j in enumerate(joints):
        rot_cols, order = [], ""
        for c in j.channels:
            if c.endswith("rotation"):
                rot_cols.append(col)
                order += c[0]
            else:
                axis = _AXIS[c[0]]
                if ji == 0:
                    root[:, axis] = data[:, col]
                else:
                    if translations is None:
                        translations = np.broadcast_to(offsets, (n_frames, n, 3)).copy()
                    translations[:, ji, axis] = data[:, col]
            col += 1
        if order:
            groups.setdefault(order, []).append((ji, rot_cols))
    for order, members in groups.items():
        idx = [m[0] for m in members]
        cols = np.array([m[1] for m in members])  # (G, len(order))
        angles = data[:, cols]  # (F, G, k)
        rotations[:, idx] = euler.to_quat(order, angles, degrees=True)
    return Motion(
        skeleton=raw_skeleton.scaled(scale),
        rotations=rotations,
        root_positions=root * scale,
        fps=1.0 / frame_time,
        translations=None if translations is None else translations * scale,
        name=name if name is not None else os.path.splitext(os.path.basename(path))[0],
    )


def _fmt(values: NDArray[np.float64], precision: int) -> list[str]:
    return [" ".join(f"{v:.{precision}f}" for v in row) for row in values]


def save_bvh(
    motion: Motion,
    path: str | PathLike[str],
    *,
    scale: float = 0.01,
    precision: int = 6,
    channels: list[tuple[str, ...]] | None = None,
) -> None:
    """Write a Motion as a BVH file.

    Parameters
    ----------
    motion : Motion
    path : str or path-like
    scale : float
        Metres per file unit (default 0.01: the file is in centimetres).
    precision : int
        Decimals written for every number.
    channels : list of tuple of str, optional
        Channel order per joint; defaults to ``motion.skeleton.channels``.
        Joints whose channels lack a rotation axis they need, or non-root
        joints with animated translations but no position channels, are
        written with the channels they need added.
    """
    sk = motion.skeleton
    chans = [tuple(c) for c in (channels or sk.channels)]
    if len(chans) != sk.n_joints:
        raise ValueError(f"Expected channels for {sk.n_joints} joints, got {len(chans)}")
    rot_needed = np.any(np.abs(quat.angle(motion.rotations)) > 1e-9, axis=0)
    for j in range(sk.n_joints):
        c = chans[j]
        rot = tuple(x for x in c if x.endswith("rotation"))
        if rot_needed[j] and len(rot) < 3:
            chans[j] = tuple(x for x in c if x.endswith("position")) + ("Zrotation", "Yrotation", "Xrotation")
        if j == 0 and not any(x.endswith("position") for x in chans[0]):
            chans[0] = ("Xposition", "Yposition", "Zposition") + chans[0]
        if j > 0 and motion.translations is not None:
            moving = np.ptp(motion.translations[:, j], axis=0).max() > 0 or not np.allclose(
                motion.translations[0, j], sk.offsets[j]
            )
            if moving and not any(x.endswith("position") for x in chans[j]):
                chans[j] = ("Xposition", "Yposition", "Zposition") + chans[j]
    n_frames = motion.n_frames
    columns = []
    for j in range(sk.n_joints):
        c = chans[j]
        rot_order = "".join(x[0] for x in c if x.endswith("rotation"))
        angles = None
        if rot_order:
            if len(rot_order) == 3:
                angles = euler.from_quat(rot_order, motion.rotations[:, j])
            else:
                # fewer than three rotation channels: only reached when the
                # joint never rotates (see above), so the angles are zero
                angles = np.zeros((n_frames, len(rot_order)))
            angles = np.unwrap(angles, period=360.0, axis=0) if n_frames > 1 else angles
        if j == 0:
            pos = motion.root_positions
        elif motion.translations is not None:
            pos = motion.translations[:, j]
        else:
            pos = np.broadcast_to(sk.offsets[j], (n_frames, 3))
        k = 0
        for x in c:
            if x.endswith("rotation"):
                assert angles is not None
                columns.append(angles[:, k])
                k += 1
            else:
                columns.append(pos[:, _AXIS[x[0]]] / scale)
    data = np.stack(columns, axis=1) if columns else np.zeros((n_frames, 0))

    out: list[str] = ["HIERARCHY"]
    children = [sk.children(j) for j in range(sk.n_joints)]
    end_sites = [sk.end_site_offsets[sk.end_site_parents == j] for j in range(sk.n_joints)]

    def write(j: int, depth: int) -> None:
        pad = "\t" * depth
        out.append(f"{pad}{'ROOT' if j == 0 else 'JOINT'} {sk.names[j]}")
        out.append(pad + "{")
        off = sk.offsets[j] / scale
        out.append(f"{pad}\tOFFSET {off[0]:.{precision}f} {off[1]:.{precision}f} {off[2]:.{precision}f}")
        out.append(f"{pad}\tCHANNELS {len(chans[j])}" + "".join(" " + x for x in chans[j]))
        for c in children[j]:
            write(c, depth + 1)
        for e in end_sites[j]:
            e = e / scale
            out.append(f"{pad}\tEnd Site")
            out.append(pad + "\t{")
            out.append(f"{pad}\t\tOFFSET {e[0]:.{precision}f} {e[1]:.{precision}f} {e[2]:.{precision}f}")
            out.append(pad + "\t}")
        out.append(pad + "}")

    write(0, 0)
    out.append("MOTION")
    out.append(f"Frames: {n_frames}")
    out.append(f"Frame Time: {1.0 / motion.fps:.10g}")
    out.extend(_fmt(data, precision))
    tmp = os.fspath(path)
    with open(tmp, "w", encoding="ascii", newline="\n") as fh:
        fh.write("\n".join(out) + "\n")
