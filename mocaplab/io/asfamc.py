"""Acclaim ASF/AMC files (the CMU motion capture database's native format).

An ASF file describes a skeleton of *bones*; an AMC file gives, frame by
frame, the values of each bone's degrees of freedom.  :func:`load_asf_amc`
reads a pair into a :class:`~mocaplab.motion.Motion`.

How the Acclaim skeleton becomes a Motion
-----------------------------------------
* **Joints** are the ``root`` followed by the bones in depth-first order of
  the ``:hierarchy`` section (children in the order listed).  Joint ``b``
  sits at the *start* of bone ``b`` and is named after it (``root``,
  ``lhipjoint``, ``lfemur``, ...).  For the CMU files this is exactly the
  joint order of the CMU BVH conversions (``Hips``, ``LHipJoint``,
  ``LeftUpLeg``, ...; see :data:`CMU_BVH_NAMES`).
* **Offsets.** Bones hanging from the root start at the root.  A bone's
  child starts at its end: child offset = parent bone ``direction * length``.
  Each leaf bone gets an End Site at its end.  ASF directions are in the
  world frame of the rest pose, so the rest pose (all rotations identity) is
  the ASF pose.
* **Rotations** (the Acclaim rule): the local rotation of bone ``b`` is
  ``L = C M C^-1``, where ``C`` is the bone's ``axis`` rotation and ``M``
  the rotation of its AMC values.  Rotation angles listed in an order (the
  ``axis`` string ``XYZ``, a bone's ``dof rx ry rz`` or the root's
  ``order``) are applied in that order about fixed axes, so ``XYZ`` means
  ``Rz @ Ry @ Rx``; ``axis`` values are read in the order of its axis
  string.  Bones with no dofs keep the identity.  The root uses its
  ``orientation`` and ``axis`` for ``C`` and the rotation entries of
  ``order`` for ``M``.
* **Root position** = the AMC translation values (``TX TY TZ`` entries of
  the root ``order``); an axis without a translation dof takes the ASF
  ``position``.
* **Units.** ``:units length v`` means lengths are in units of
  ``1 / v`` inch (the CMU files say ``length 0.45``), so the scale is
  ``0.0254 / v`` metres per unit; ``angle deg`` or ``angle rad`` sets the
  unit of ASF angles and of AMC values unless the AMC file says
  ``:DEGREES`` or ``:RADIANS`` itself.
* **Frames.** AMC frame numbers must count up by one.  In a
  ``:FULLY-SPECIFIED`` file every bone with dofs must appear in every frame;
  otherwise a missing bone keeps its value from the previous frame (zero in
  the first).  The Acclaim format carries no frame rate: ``fps`` (default
  120, the CMU capture rate) labels the result.

Bone translation and length dofs (``tx ty tz l``) are not supported (no CMU
file has them) and raise :class:`~mocaplab.io.MocapFormatError`, like every
other problem in either file: it names the file, the line and what was
expected.

Paths and limits
----------------
* **Paths** are handled as by :func:`~mocaplab.io.load_bvh`: ``str`` or
  ``os.PathLike``, ``bytes`` decoded with :func:`os.fsdecode`; a missing
  file, a dangling symbolic link, a symbolic-link loop, an empty path, a
  directory, a device or pipe, or an unreadable file is a
  :class:`~mocaplab.io.MocapFormatError` naming that path (line 0), for the
  ASF and the AMC alike.  No ``OSError`` escapes.
* **Text** is UTF-8; a byte that is not (a Latin-1 accent in a header
  comment, as in some HDM05 files) is read as Latin-1 with a warning naming
  its file, line and byte (:func:`~mocaplab.io.bvh.decode_text`).
* **Work is linear in the file**: an ASF of 20,000 bones (a chain or a
  star) parses in a fraction of a second; AMC frame numbers longer than
  :data:`~mocaplab.io.bvh.MAX_INTEGER_DIGITS` digits are rejected before
  conversion.
* **Frame rate.** ``fps`` must lie in :data:`~mocaplab.io.bvh.FPS_RANGE`
  (0.1 to 10,000 frames per second), the range the BVH reader accepts.
* **Overflow.** Values that overflow once converted to metres are reported
  on the line that holds them: an AMC root translation on its AMC line, a
  bone's direction and length on the ASF line that begins the bone.

Longer than 800 lines because the ASF and AMC readers and the writer share one grammar, its error positions (file, line, what was expected) and the unit and axis conventions.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from os import PathLike

import numpy as np
from numpy.typing import NDArray

from .. import quat
from ..motion import Motion, Skeleton, _owned
from . import euler
from ._hierarchy import check_reach
from .bvh import (
    FPS_RANGE,
    MAX_INTEGER_DIGITS,
    _to_float,
    as_path,
    check_scale,
    decode_text,
    header_integer,
    read_text,
    split_lines,
)
from .errors import MocapFormatError

__all__ = ["load_asf_amc", "parse_asf", "parse_amc", "Asf", "AsfBone", "CMU_BVH_NAMES", "INCH_M"]

INCH_M = 0.0254

#: Joint names of the CMU BVH conversions (cgspeed) for the ASF bone names.
CMU_BVH_NAMES: dict[str, str] = {
    "root": "Hips",
    "lhipjoint": "LHipJoint",
    "lfemur": "LeftUpLeg",
    "ltibia": "LeftLeg",
    "lfoot": "LeftFoot",
    "ltoes": "LeftToeBase",
    "rhipjoint": "RHipJoint",
    "rfemur": "RightUpLeg",
    "rtibia": "RightLeg",
    "rfoot": "RightFoot",
    "rtoes": "RightToeBase",
    "lowerback": "LowerBack",
    "upperback": "Spine",
    "thorax": "Spine1",
    "lowerneck": "Neck",
    "upperneck": "Neck1",
    "head": "Head",
    "lclavicle": "LeftShoulder",
    "lhumerus": "LeftArm",
    "lradius": "LeftForeArm",
    "lwrist": "LeftHand",
    "lhand": "LeftFingerBase",
    "lfingers": "LeftHandIndex1",
    "lthumb": "LThumb",
    "rclavicle": "RightShoulder",
    "rhumerus": "RightArm",
    "rradius": "RightForeArm",
    "rwrist": "RightHand",
    "rhand": "RightFingerBase",
    "rfingers": "RightHandIndex1",
    "rthumb": "RThumb",
}

_ROT_DOFS = ("rx", "ry", "rz")
_ROOT_DOFS = ("tx", "ty", "tz", "rx", "ry", "rz")


@dataclass(frozen=True)
class AsfBone:
    """One ``begin ... end`` block of an ASF ``:bonedata`` section (file units)."""

    name: str
    direction: tuple[float, float, float]
    length: float
    axis: tuple[float, float, float] = (0.0, 0.0, 0.0)
    axis_order: str = "XYZ"
    dofs: tuple[str, ...] = ()
    line: int = 0


@dataclass(frozen=True)
class Asf:
    """A parsed ASF skeleton (file units and angle unit as written)."""

    path: str
    length_unit: float
    degrees: bool
    root_order: tuple[str, ...]
    root_axis_order: str
    root_position: tuple[float, float, float]
    root_orientation: tuple[float, float, float]
    bones: dict[str, AsfBone]
    #: joint order: "root" then bones depth first
    order: list[str] = field(default_factory=list)
    #: parent joint index of each entry of ``order``
    parents: list[int] = field(default_factory=list)

    @property
    def scale(self) -> float:
        """Metres per ASF length unit, ``0.0254 / length``."""
        return INCH_M / self.length_unit


# ---------------------------------------------------------------------- ASF


def _numbers(path: str, line: int, toks: list[str], count: int, what: str) -> list[float]:
    if len(toks) < count:
        raise MocapFormatError(path, line, f"{count} numbers for {what}", f"{len(toks)}")
    out = []
    for t in toks[:count]:
        v = _to_float(t)
        if v is None:
            raise MocapFormatError(path, line, f"a number for {what}", repr(t[:40]))
        if not math.isfinite(v):
            raise MocapFormatError(path, line, f"a finite number for {what}", repr(t[:40]))
        out.append(v)
    return out


def _axis_order(path: str, line: int, tok: str) -> str:
    up = tok.upper()
    if len(up) != 3 or set(up) != {"X", "Y", "Z"}:
        raise MocapFormatError(path, line, "an axis order such as 'XYZ'", repr(tok[:40]))
    return up


def parse_asf(path: str | bytes | PathLike[str]) -> Asf:
    """Parse an ASF file (no unit conversion); see :func:`load_asf_amc`."""
    path = as_path(path)
    return _parse_asf_text(path, read_text(path, "an ASF file"))


def _parse_asf_text(path: str, text: str) -> Asf:
    """:func:`parse_asf` of the file's text (``path`` names it in errors)."""
    lines = split_lines(text)
    while lines and not lines[-1].strip():
        lines.pop()  # so that "end of file" names the last line with text
    if not lines:
        raise MocapFormatError(path, 1, "an ASF skeleton (':root', ':bonedata', ':hierarchy')", "an empty file")
    section = ""
    seen: dict[str, int] = {}
    length_unit = 1.0
    degrees = True
    root_order: tuple[str, ...] | None = None
    root_axis = "XYZ"
    root_position = (0.0, 0.0, 0.0)
    root_orientation = (0.0, 0.0, 0.0)
    bones: dict[str, AsfBone] = {}
    bone: dict[str, object] | None = None
    bone_line = 0
    in_hierarchy = False
    hierarchy_done = False
    children: dict[str, list[str]] = {}
    child_parent: dict[str, str] = {}

    def close_bone(number: int) -> None:
        nonlocal bone
        assert bone is not None
        for key in ("name", "direction", "length"):
            if key not in bone:
                raise MocapFormatError(path, number, f"a '{key}' line in the bone beginning on line {bone_line}", "none")
        name = str(bone["name"])
        if name in bones or name == "root":
            raise MocapFormatError(path, bone_line, "unique bone names (other than 'root')", f"a second {name!r}")
        direction: list[float] = bone["direction"]  # type: ignore[assignment]
        norm = math.hypot(*direction)  # plain floats: a numpy call per bone is most of the time on big files
        if not (math.isfinite(norm) and norm > 0):
            raise MocapFormatError(path, bone_line, f"a non-zero direction for bone {name!r}", "zero")
        length = float(bone["length"])  # type: ignore[arg-type]
        if length < 0:
            raise MocapFormatError(path, bone_line, f"a length >= 0 for bone {name!r}", f"{length:g}")
        bones[name] = AsfBone(
            name=name,
            direction=(direction[0] / norm, direction[1] / norm, direction[2] / norm),
            length=length,
            axis=tuple(bone.get("axis", (0.0, 0.0, 0.0))),  # type: ignore[arg-type]
            axis_order=str(bone.get("axis_order", "XYZ")),
            dofs=tuple(bone.get("dofs", ())),  # type: ignore[arg-type]
            line=bone_line,
        )
        bone = None

    for number, text in enumerate(lines, start=1):
        toks = text.split()
        if not toks or toks[0].startswith("#"):
            continue
        key = toks[0]
        if key.startswith(":"):
            if bone is not None:
                raise MocapFormatError(path, number, f"'end' closing the bone beginning on line {bone_line}", repr(key))
            if in_hierarchy:
                raise MocapFormatError(path, number, "'end' closing the hierarchy", repr(key))
            section = key.lower()
            seen.setdefault(section, number)
            if section == "name" or section == "version":
                pass
            continue
        if section == ":units":
            if key == "length":
                (length_unit,) = _numbers(path, number, toks[1:], 1, "the length unit")
                if length_unit <= 0:
                    raise MocapFormatError(path, number, "a positive length unit", toks[1])
                if not math.isfinite(INCH_M / length_unit):
                    raise MocapFormatError(
                        path, number, "a length unit whose scale (0.0254 / length metres per unit) is finite", toks[1]
                    )
            elif key == "angle":
                unit = toks[1].lower() if len(toks) > 1 else ""
                if unit in ("deg", "degree", "degrees"):
                    degrees = True
                elif unit in ("rad", "radian", "radians"):
                    degrees = False
                else:
                    raise MocapFormatError(path, number, "'angle deg' or 'angle rad'", repr(text.strip()[:40]))
            # mass and other units do not matter here
        elif section == ":root":
            if key == "order":
                dofs = tuple(t.lower() for t in toks[1:])
                bad = [t for t in dofs if t not in _ROOT_DOFS]
                if bad or len(set(dofs)) != len(dofs):
                    raise MocapFormatError(
                        path, number, "root order entries from TX TY TZ RX RY RZ, each once", repr(" ".join(toks[1:])[:60])
                    )
                root_order = dofs
            elif key == "axis":
                if len(toks) < 2:
                    raise MocapFormatError(path, number, "an axis order such as 'XYZ'", "none")
                root_axis = _axis_order(path, number, toks[1])
            elif key == "position":
                root_position = tuple(_numbers(path, number, toks[1:], 3, "the root position"))  # type: ignore[assignment]
            elif key == "orientation":
                root_orientation = tuple(_numbers(path, number, toks[1:], 3, "the root orientation"))  # type: ignore[assignment]
            else:
                raise MocapFormatError(path, number, "'order', 'axis', 'position' or 'orientation'", repr(key[:40]))
        elif section == ":bonedata":
            if bone is None:
                if key != "begin":
                    raise MocapFormatError(path, number, "'begin' opening a bone", repr(key[:40]))
                bone = {}
                bone_line = number
                continue
            if key == "end":
                close_bone(number)
            elif key == "begin":
                raise MocapFormatError(path, number, f"'end' closing the bone beginning on line {bone_line}", "'begin'")
            elif key == "name":
                if len(toks) != 2:
                    raise MocapFormatError(path, number, "'name <bone>'", repr(text.strip()[:40]))
                bone["name"] = toks[1]
            elif key == "direction":
                bone["direction"] = _numbers(path, number, toks[1:], 3, "the bone direction")
            elif key == "length":
                bone["length"] = _numbers(path, number, toks[1:], 1, "the bone length")[0]
            elif key == "axis":
                bone["axis"] = _numbers(path, number, toks[1:], 3, "the bone axis")
                bone["axis_order"] = _axis_order(path, number, toks[4]) if len(toks) > 4 else "XYZ"
            elif key == "dof":
                dofs = tuple(t.lower() for t in toks[1:])
                bad = [t for t in dofs if t not in _ROT_DOFS]
                if bad:
                    raise MocapFormatError(
                        path,
                        number,
                        "rotation dofs rx, ry, rz (bone translation and length dofs are not supported)",
                        repr(bad[0][:40]),
                    )
                if len(set(dofs)) != len(dofs):
                    raise MocapFormatError(path, number, "each dof once", repr(" ".join(toks[1:])[:40]))
                bone["dofs"] = dofs
            # id, limits (and their continuation lines), bodymass, cofmass: not needed
        elif section == ":hierarchy":
            if hierarchy_done:
                raise MocapFormatError(path, number, "a new section after the hierarchy's 'end'", repr(key[:40]))
            if not in_hierarchy:
                if key != "begin":
                    raise MocapFormatError(path, number, "'begin' opening the hierarchy", repr(key[:40]))
                in_hierarchy = True
                continue
            if key == "end":
                in_hierarchy = False
                hierarchy_done = True
                continue
            parent = key
            if parent != "root" and parent not in bones:
                raise MocapFormatError(path, number, "a bone defined in ':bonedata' (or 'root')", repr(parent[:40]))
            for child in toks[1:]:
                if child not in bones:
                    raise MocapFormatError(path, number, "a bone defined in ':bonedata'", repr(child[:40]))
                if child in child_parent:
                    raise MocapFormatError(
                        path, number, f"one parent for bone {child!r}", f"{child_parent[child]!r} and {parent!r}"
                    )
                child_parent[child] = parent
                children.setdefault(parent, []).append(child)
        # other sections (:version, :name, :documentation, :skin, ...) are ignored
    last = len(lines)
    if bone is not None:
        raise MocapFormatError(path, last, f"'end' closing the bone beginning on line {bone_line}", "end of file")
    if in_hierarchy:
        raise MocapFormatError(path, last, "'end' closing the hierarchy", "end of file (truncated?)")
    for required in (":root", ":bonedata", ":hierarchy"):
        if required not in seen:
            raise MocapFormatError(path, last, f"a '{required}' section", "none")
    if not hierarchy_done:
        raise MocapFormatError(path, last, "'begin' ... 'end' in the ':hierarchy' section", "none")
    if root_order is None:
        raise MocapFormatError(path, seen[":root"], "an 'order' line in ':root'", "none")
    # depth-first order from the root, children as listed (iterative)
    order: list[str] = []
    parents: list[int] = []
    stack: list[tuple[str, int]] = [("root", -1)]
    while stack:
        name, parent_index = stack.pop()
        order.append(name)
        parents.append(parent_index)
        here = len(order) - 1
        for child in reversed(children.get(name, [])):
            stack.append((child, here))
    placed = set(order)
    missing = [b for b in bones if b not in placed]
    if missing:
        b = bones[missing[0]]
        raise MocapFormatError(path, b.line, f"bone {b.name!r} attached to the hierarchy below 'root'", "no path from the root")
    return Asf(
        path=path,
        length_unit=length_unit,
        degrees=degrees,
        root_order=root_order,
        root_axis_order=root_axis,
        root_position=root_position,
        root_orientation=root_orientation,
        bones=bones,
        order=order,
        parents=parents,
    )


# ---------------------------------------------------------------------- AMC


def _dof_count(asf: Asf) -> dict[str, int]:
    counts = {"root": len(asf.root_order)}
    for name, b in asf.bones.items():
        counts[name] = len(b.dofs)
    return counts


def parse_amc(path: str | bytes | PathLike[str], asf: Asf) -> tuple[dict[str, NDArray[np.float64]], int, bool | None]:
    """Parse an AMC file against its skeleton.

    Returns
    -------
    values : dict of str to ndarray, shape (F, n_dofs)
        AMC values per bone (``root`` included), in the bone's dof order, in
        the file's angle unit; bones without dofs are absent.
    n_frames : int
    degrees : bool or None
        ``True``/``False`` if the file says ``:DEGREES``/``:RADIANS``, else None.
    """
    path = as_path(path)
    values, n_frames, degrees, _ = _parse_amc_text(path, read_text(path, "an AMC file"), asf)
    return values, n_frames, degrees


#: AMC values per bone, frame count, angle unit, and the line each bone's value of each frame came from
_AmcResult = tuple[dict[str, NDArray[np.float64]], int, bool | None, dict[str, NDArray[np.int64]]]


def _parse_amc_text(path: str, text: str, asf: Asf) -> _AmcResult:
    """:func:`parse_amc` of the file's text, with the source line of every value row.

    ``lines[bone][f]`` is the 1-based line that gave ``values[bone][f]`` (for
    a bone missing from a frame of a file that is not fully specified, the
    line its value was kept from, or the frame-number line in the first frame).
    """
    lines = split_lines(text)
    while lines and not lines[-1].strip():
        lines.pop()
    counts = _dof_count(asf)
    degrees: bool | None = None
    fully = False
    start = None
    for i, text in enumerate(lines):
        s = text.strip()
        if not s or s.startswith("#"):
            continue
        if s.startswith(":"):
            word = s.split()[0].upper()
            if word == ":FULLY-SPECIFIED":
                fully = True
            elif word == ":DEGREES":
                degrees = True
            elif word == ":RADIANS":
                degrees = False
            continue
        start = i
        break
    if start is None:
        what = "an empty file" if not lines else "end of file"
        raise MocapFormatError(path, max(len(lines), 1), "AMC frames (a frame number, then one line per bone)", what)
    body = lines[start:]
    while body and not body[-1].strip():
        body.pop()
    result = _fast_amc(body, start, counts)
    if result is None:
        result = _slow_amc(path, body, start, counts, fully)
    values, n_frames, where = result
    return values, n_frames, degrees, where


def _frame_number(s: str) -> int | None:
    return header_integer(s)


_Frames = tuple[dict[str, NDArray[np.float64]], int, dict[str, NDArray[np.int64]]]


def _fast_amc(body: list[str], start: int, counts: dict[str, int]) -> _Frames | None:
    """Read a regular file (every frame the same bone lines in the same order,
    no comments or blank lines) as one table; None if the file is not that
    regular or anything in it is wrong, so that :func:`_slow_amc` reads it
    line by line and reports the problem precisely.

    Each bone's name is replaced by ``nan`` at the start of its lines, the
    lines of a frame are joined into one row and numpy reads the table.  The
    name columns must then be NaN and the value columns finite: a line with a
    wrong name or a wrong number of values breaks that pattern.
    """
    if not body or _frame_number(body[0].strip()) is None:
        return None
    k = 1
    while k < len(body) and _frame_number(body[k].strip()) is None:
        k += 1
    if len(body) % k:
        return None
    n_frames = len(body) // k
    first = _frame_number(body[0].strip())
    assert first is not None
    if [s.strip() for s in body[0::k]] != [str(first + f) for f in range(n_frames)]:
        return None
    names = [body[r].split(None, 1)[0] if body[r].strip() else "" for r in range(1, k)]
    if len(set(names)) != len(names) or sorted(names) != sorted(n for n, c in counts.items() if c > 0):
        return None
    columns = [body[0::k]]
    for r, name in enumerate(names, start=1):
        column = "\n" + "\n".join(body[r::k])
        if column.count("\n" + name) != n_frames:  # a line of another bone (or a literal 'nan'): read it slowly
            return None
        column = column.replace("\n" + name, "\nnan")
        columns.append(column.split("\n")[1:])
    rows = list(map(" ".join, zip(*columns, strict=True)))
    try:
        table = np.loadtxt(rows, dtype=np.float64, ndmin=2, comments=None)
    except ValueError:
        return None
    width = 1 + sum(1 + counts[n] for n in names)
    if table.shape != (n_frames, width):
        return None
    out: dict[str, NDArray[np.float64]] = {}
    where: dict[str, NDArray[np.int64]] = {}
    col = 1
    for r, name in enumerate(names, start=1):
        n = counts[name]
        if not np.isnan(table[:, col]).all():
            return None
        values = table[:, col + 1 : col + 1 + n]
        if not np.isfinite(values).all():
            return None
        out[name] = np.ascontiguousarray(values)
        where[name] = start + 1 + r + k * np.arange(n_frames, dtype=np.int64)
        col += 1 + n
    return out, n_frames, where


def _slow_amc(path: str, body: list[str], start: int, counts: dict[str, int], fully: bool) -> _Frames:
    """Line-by-line reading with precise errors."""
    dof_bones = [n for n, c in counts.items() if c > 0]
    tokens: dict[str, list[str]] = {n: [] for n in dof_bones}
    lines_of: dict[str, list[int]] = {n: [] for n in dof_bones}
    frame = None  # current frame number
    frame_line = 0
    present: set[str] = set()
    n_frames = 0

    def finish_frame(at: int) -> None:
        missing = [n for n in dof_bones if n not in present]
        if missing and fully:
            raise MocapFormatError(
                path, at, f"a line for bone {missing[0]!r} in frame {frame} (the file is :FULLY-SPECIFIED)", "none"
            )
        for n in missing:  # keep the previous value (zero in the first frame)
            prev = tokens[n][-counts[n] :] if n_frames > 1 else ["0"] * counts[n]
            tokens[n].extend(prev)
            lines_of[n].append(lines_of[n][-1] if n_frames > 1 else frame_line)

    for i, text in enumerate(body):
        number = start + i + 1
        toks = text.split()
        if not toks or toks[0].startswith("#"):
            continue
        if len(toks) == 1 and toks[0] not in counts:
            value = _frame_number(toks[0])
            if value is None:
                if toks[0].isascii() and toks[0].isdigit():
                    raise MocapFormatError(
                        path, number, f"a frame number of at most {MAX_INTEGER_DIGITS} digits", f"{len(toks[0])} digits"
                    )
                raise MocapFormatError(path, number, "a frame number or a bone line", repr(toks[0][:40]))
            if frame is not None:
                finish_frame(number - 1)
                if value != frame + 1:
                    raise MocapFormatError(path, number, f"frame number {frame + 1}", str(value))
            frame = value
            frame_line = number
            present = set()
            n_frames += 1
            continue
        name = toks[0]
        if frame is None:
            raise MocapFormatError(path, number, "a frame number", repr(text.strip()[:40]))
        if name not in counts:
            raise MocapFormatError(path, number, "a bone of the ASF skeleton", repr(name[:40]))
        n = counts[name]
        if len(toks) - 1 != n:
            raise MocapFormatError(path, number, f"{n} value(s) for bone {name!r}", str(len(toks) - 1))
        if n == 0:
            continue
        if name in present:
            raise MocapFormatError(path, number, f"bone {name!r} once in frame {frame}", "a second line")
        present.add(name)
        for t in toks[1:]:
            v = _to_float(t)
            if v is None:
                raise MocapFormatError(path, number, "a number", repr(t[:30]))
            if not math.isfinite(v):
                raise MocapFormatError(path, number, "a finite number", repr(t[:30]))
        tokens[name].extend(toks[1:])
        lines_of[name].append(number)
    if frame is None:
        raise MocapFormatError(path, start + len(body), "AMC frames", "none")
    finish_frame(start + len(body))
    values = {n: np.array(tokens[n], dtype=float).reshape(n_frames, counts[n]) for n in dof_bones}
    return values, n_frames, {n: np.array(lines_of[n], dtype=np.int64) for n in dof_bones}


# ------------------------------------------------------------------ loading


def _fixed_axes_quat(order: str, angles: NDArray[np.float64], degrees: bool) -> NDArray[np.float64]:
    """Rotations applying ``angles`` about fixed axes in the order ``order``.

    Fixed-axis (extrinsic) ``"XYZ"`` is ``Rz @ Ry @ Rx``, the intrinsic
    ``"ZYX"`` of :func:`mocaplab.io.euler.to_quat` with the angles reversed.
    """
    return euler.to_quat(order[::-1], angles[..., ::-1], degrees=degrees)


def load_asf_amc(
    asf_path: str | bytes | PathLike[str],
    amc_path: str | bytes | PathLike[str],
    *,
    name: str | None = None,
    fps: float = 120.0,
    scale: float | None = None,
) -> Motion:
    """Read an Acclaim skeleton (ASF) and motion (AMC) into a Motion.

    Parameters
    ----------
    asf_path, amc_path : str or path-like
        ``bytes`` paths are decoded with :func:`os.fsdecode`.
    name : str, optional
        Label (default: the AMC file stem).
    fps : float
        Frame rate; the format has none (120 for the CMU database).  Must lie
        in :data:`~mocaplab.io.bvh.FPS_RANGE` (0.1 to 10,000).
    scale : float, optional
        Metres per ASF length unit; default from the ASF's ``:units length``
        (``0.0254 / length``, 0.056444 m for the CMU files).

    Returns
    -------
    Motion
        Joints ``root`` then the bones in depth-first hierarchy order, named
        as in the ASF, in metres (see the module notes for every convention).

    Raises
    ------
    MocapFormatError
        For any malformed ASF or AMC file (file, line and expectation), and
        for any problem with either path (missing, dangling link, link loop,
        empty, a directory, ...: see the module notes).
    ValueError
        For an ``fps`` outside :data:`~mocaplab.io.bvh.FPS_RANGE` or a
        ``scale`` that is not a positive finite number.
    TypeError
        For a path that is not a str, bytes or os.PathLike.

    Examples
    --------
    >>> from mocaplab.data import mirror_dir
    >>> folder = mirror_dir() / "asfamc" / "16"
    >>> walk = load_asf_amc(folder / "16.asf", folder / "16_15.amc")
    >>> walk.skeleton.names[:3], walk.n_frames, walk.fps
    (('root', 'lhipjoint', 'lfemur'), 471, 120.0)
    """
    asf_file = as_path(asf_path, "asf_path")
    amc_file = as_path(amc_path, "amc_path")
    _check_options(fps, scale)
    asf = _parse_asf_text(asf_file, read_text(asf_file, "an ASF file"))
    amc = _parse_amc_text(amc_file, read_text(amc_file, "an AMC file"), asf)
    return _motion_from_acclaim(asf, amc_file, amc, name=name, fps=fps, scale=scale)


def load_asf_amc_bytes(
    asf_raw: bytes,
    asf_path: str,
    amc_raw: bytes,
    amc_path: str,
    *,
    name: str | None = None,
    fps: float = 120.0,
    scale: float | None = None,
) -> Motion:
    """:func:`load_asf_amc` of files' bytes already in memory (the paths name them in errors).

    For callers that must parse exactly the bytes they checked (the data
    registry hashes the files, then parses those same bytes).
    """
    _check_options(fps, scale)
    asf = _parse_asf_text(asf_path, decode_text(asf_path, asf_raw))
    amc = _parse_amc_text(amc_path, decode_text(amc_path, amc_raw), asf)
    return _motion_from_acclaim(asf, amc_path, amc, name=name, fps=fps, scale=scale)


def _check_options(fps: object, scale: object) -> None:
    if not (
        isinstance(fps, (int, float, np.integer, np.floating))
        and not isinstance(fps, bool)
        and FPS_RANGE[0] <= fps <= FPS_RANGE[1]  # type: ignore[operator]
    ):
        raise ValueError(f"Expected `fps` from {FPS_RANGE[0]:g} to {FPS_RANGE[1]:g} frames per second, got {fps!r}")
    check_scale(scale, "metres per ASF unit")


def _motion_from_acclaim(
    asf: Asf, amc_path: str, amc: _AmcResult, *, name: str | None, fps: float, scale: float | None
) -> Motion:
    values, n_frames, amc_degrees, value_lines = amc
    amc_deg = asf.degrees if amc_degrees is None else amc_degrees
    unit = asf.scale if scale is None else float(scale)
    names = asf.order
    n = len(names)
    parents = np.array(asf.parents, dtype=np.int64)

    # skeleton: joint b at the start of bone b
    ends = np.zeros((n, 3))  # bone vector (direction * length), file units
    for j, b in enumerate(names[1:], start=1):
        bone = asf.bones[b]
        ends[j] = np.asarray(bone.direction) * bone.length
    offsets = np.zeros((n, 3))
    offsets[0] = asf.root_position
    for j in range(1, n):
        offsets[j] = ends[parents[j]] if parents[j] > 0 else 0.0
    has_child = np.zeros(n, dtype=bool)
    has_child[parents[1:]] = True
    leaves = [j for j in range(1, n) if not has_child[j]]

    # local rotations L = C M C^-1, grouped by dof order
    rotations = np.zeros((n_frames, n, 4))
    rotations[..., 3] = 1.0
    axis_angles = np.zeros((n, 3))
    by_axis_order: dict[str, list[int]] = {}
    groups: dict[str, list[int]] = {}
    for j, b in enumerate(names):
        if b == "root":
            axis_order, axis_angles[j] = asf.root_axis_order, asf.root_orientation
            order = "".join(d[1].upper() for d in asf.root_order if d[0] == "r")
        else:
            bone = asf.bones[b]
            axis_order, axis_angles[j] = bone.axis_order, bone.axis
            order = "".join(d[1].upper() for d in bone.dofs)
        by_axis_order.setdefault(axis_order, []).append(j)
        if order:
            groups.setdefault(order, []).append(j)
    axes_q = np.empty((n, 4))
    for axis_order, joints in by_axis_order.items():  # one call per axis order, not per bone
        axes_q[joints] = _fixed_axes_quat(axis_order, axis_angles[joints], asf.degrees)
    for order, joints in groups.items():
        cols = []
        for j in joints:
            b = names[j]
            v = values[b]
            if b == "root":
                v = v[:, [k for k, d in enumerate(asf.root_order) if d[0] == "r"]]
            cols.append(v)
        angles = np.stack(cols, axis=1)  # (F, G, k)
        m = _fixed_axes_quat(order, angles, amc_deg)
        # C M C^-1 keeps the scalar part of M and rotates its vector part by C
        c_matrix = quat.to_matrix(axes_q[joints])  # (G, 3, 3)
        rotations[:, joints, :3] = np.einsum("gij,fgj->fgi", c_matrix, m[..., :3])
        rotations[:, joints, 3] = m[..., 3]
    root = np.empty((n_frames, 3))
    root[:] = asf.root_position
    if "root" in values:
        for k, d in enumerate(asf.root_order):
            if d[0] == "t":
                root[:, "xyz".index(d[1])] = values["root"][:, k]
    with np.errstate(over="ignore"):  # overflow is reported below
        root *= unit
        scaled = offsets * unit
        end_offsets = ends[leaves] * unit
    _report_overflow(asf, amc_path, names, parents, leaves, root, scaled, end_offsets, value_lines, unit)
    skeleton = Skeleton(
        names=tuple(names),
        parents=parents,
        offsets=scaled,
        end_site_parents=np.array(leaves, dtype=np.int64),
        end_site_offsets=end_offsets.reshape(-1, 3),
    )
    motion = Motion(
        skeleton=skeleton,
        rotations=_owned(rotations),
        root_positions=_owned(root),
        fps=float(fps),
        name=name if name is not None else os.path.splitext(os.path.basename(amc_path))[0],
    )
    check_reach(amc_path, motion, skeleton_path=asf.path)
    return motion


def _report_overflow(
    asf: Asf,
    amc_path: str,
    names: list[str],
    parents: NDArray[np.int64],
    leaves: list[int],
    root: NDArray[np.float64],
    offsets: NDArray[np.float64],
    end_offsets: NDArray[np.float64],
    value_lines: dict[str, NDArray[np.int64]],
    unit: float,
) -> None:
    """MocapFormatError on the line whose values overflowed in metres, if any did."""
    expected = f"values that stay finite in metres (scale {unit:g})"
    bad_root = ~np.isfinite(root)
    if bad_root.any():
        frame, axis = (int(i) for i in np.argwhere(bad_root)[0])
        translated = any(d == "t" + "xyz"[axis] for d in asf.root_order)
        if translated and "root" in value_lines:
            line = int(value_lines["root"][frame])
            raise MocapFormatError(amc_path, line, f"root translation {expected}", "an overflow")
        raise MocapFormatError(asf.path, 0, f"a root position {expected}", "an overflow")
    bad = np.flatnonzero(~np.isfinite(offsets).all(axis=1))
    if bad.size:
        j = int(bad[0])
        if j == 0:
            raise MocapFormatError(asf.path, 0, f"a root position {expected}", "an overflow")
        bone = asf.bones[names[int(parents[j])]]
        raise MocapFormatError(asf.path, bone.line, f"bone {bone.name!r} direction * length {expected}", "an overflow")
    bad = np.flatnonzero(~np.isfinite(end_offsets).all(axis=1))
    if bad.size:
        bone = asf.bones[names[leaves[int(bad[0])]]]
        raise MocapFormatError(asf.path, bone.line, f"bone {bone.name!r} direction * length {expected}", "an overflow")
