"""Autodesk FBX files: the skeleton and one animation stack as a Motion.

:func:`load_fbx` reads binary FBX (6.1 to 7.7: the files Mixamo, Blender,
Maya and MotionBuilder write) and ASCII FBX.

Which reader, and why
---------------------
The file is parsed by **ufbx** (its Python bindings, ``pip install ufbx``), a
single-file C reader that is fuzzed, keeps no global state and evaluates FBX
transforms completely: pre- and post-rotations, rotation order, rotation and
scaling pivots and offsets, scale inheritance modes and animation layers.
Assimp's bindings were the other candidate; they need a system library, bake
pre/post rotations into extra ``$AssimpFbx$`` nodes that must be folded back,
and their Python package lags the C++ library.

The bindings are young (0.0.5) and hand out every scene element (node,
stack, curve) as a reference Python does not own: dropping one frees it
while the scene still points at it, and the interpreter crashes later.  So
ufbx runs in a short-lived child process (``_ufbx_worker.py`` beside this
module, started with the same interpreter): the worker gives each element
the reference it lacks, never releases anything, sends back plain numbers
(local transforms per frame, names, parents) and exits.  A crash of the
bindings ends the worker, not the user's Python; it is reported as a
:class:`~mocaplab.io.MocapFormatError`.  Starting the worker costs about a
tenth of a second (``benchmarks/bench_io.py``).

How the file becomes a Motion
-----------------------------
* **Skeleton.** The joints are the *bone* nodes (FBX ``LimbNode``, ``Limb``
  and ``Root`` skeleton attributes); meshes, cameras and other nodes are
  ignored, so "Without Skin" downloads read the same as skinned ones.  A
  skeleton is a bone with no bone above it plus every bone below it (a joint's
  parent is its nearest bone ancestor).  Joints are in depth-first order of
  the file's hierarchy and keep the file's names (``mixamorig:Hips``; the
  naming table knows the Mixamo prefixes).  A file with several skeletons
  needs ``skeleton=`` (the name of a root joint, or of a node above it such
  as Blender's armature).
* **Animation.** The first animation stack (take), or ``take=`` (a name or an
  index).  It is sampled from the stack's start to its end at the file's
  frame rate (``GlobalSettings``), or at ``fps=``: frame ``i`` is the scene
  evaluated by ufbx at ``start + i / fps``.
* **Units and axes.** ufbx turns the file's axes (``GlobalSettings``
  ``UpAxis``, ``FrontAxis``, ``CoordAxis`` and their signs) into right-handed
  Y up; lengths are multiplied by the file's unit (``UnitScaleFactor``
  centimetres: Mixamo and Maya files are in centimetres), or by ``scale``
  when given.
* **Transforms.** ufbx evaluates every joint's local transform per frame
  (pre/post rotations, pivots and rotation order included); they are
  composed with those of the nodes above (an armature, the axis conversion)
  into world matrices.  Joint frames are the rest pose's turned to the world
  axes, as in BVH: with every local rotation the identity the skeleton
  stands in the file's rest pose, and a joint's offset is its rest position
  minus its parent's.  The world rotation of a joint is its matrix with the
  scale divided out, times the inverse of its rest rotation; the local
  rotation is ``inv(parent world rotation) * world rotation``; the animated
  offset is the child's position seen from the parent's frame.  When that
  offset stays put over the clip (within :data:`OFFSET_TOLERANCE` metres) it
  is the skeleton's offset; otherwise the joint's animated translation goes
  to :attr:`Motion.translations`.  Forward kinematics of the result gives
  back the evaluated world positions.
* **Channels.** Each joint's BVH channels follow its FBX rotation order
  (``eEulerXYZ``, which rotates about X first, becomes
  ``Zrotation Yrotation Xrotation``), so :func:`~mocaplab.io.save_bvh`
  writes the same Euler angles a DCC tool shows.

Paths and limits
----------------
* Every problem raises :class:`~mocaplab.io.MocapFormatError` naming the
  file: a path that is missing or not a regular file (as for BVH), bytes that
  are not FBX, a truncated file, a file without a skeleton or without an
  animation of it, several skeletons without ``skeleton=``, an unknown
  ``take``.
* **Memory is bounded by the file.** Before ufbx sees a binary file, every
  node record is walked: a record that ends past the end of the file is the
  "truncated file" error, and an array whose element count needs more bytes
  than it stores (raw arrays) or more than :data:`MAX_DEFLATE_RATIO` times
  its compressed bytes (DEFLATE cannot expand more) is rejected, so no header
  value can make the reader allocate more than a fixed multiple of the file.
  The number of frames sampled is bounded by the keys the stack's curves
  hold (see :data:`MAX_UNKEYED_FRAMES`).
"""

from __future__ import annotations

import math
import os
import pickle
import struct
import subprocess
import sys
from os import PathLike
from typing import Any

import numpy as np

from ..motion import FPS_RANGE, Motion
from ._hierarchy import OFFSET_TOLERANCE, motion_from_transforms
from .bvh import as_path, check_scale, read_bytes
from .errors import MocapFormatError

__all__ = ["load_fbx", "OFFSET_TOLERANCE", "MAX_DEFLATE_RATIO", "MAX_UNKEYED_FRAMES"]

#: The most a DEFLATE stream expands (1032:1, the format's limit): a
#: compressed array whose element count needs more is rejected unread.
MAX_DEFLATE_RATIO = 1032

#: Frames that may be sampled whatever the curves hold; beyond, a stack may
#: not be sampled into more than twice as many frames as its longest curve
#: has keys (a header's time span cannot make the reader allocate at will).
MAX_UNKEYED_FRAMES = 100_000

_BINARY_MAGIC = b"Kaydara FBX Binary  \x00"
_ARRAY_SIZES = {ord("f"): 4, ord("i"): 4, ord("d"): 8, ord("l"): 8, ord("b"): 1}
_SCALAR_SIZES = {ord("Y"): 2, ord("C"): 1, ord("I"): 4, ord("F"): 4, ord("D"): 8, ord("L"): 8}


def load_fbx(
    path: str | bytes | PathLike[str],
    *,
    take: str | int | None = None,
    fps: float | None = None,
    skeleton: str | None = None,
    scale: float | None = None,
    name: str | None = None,
) -> Motion:
    """Read the skeleton and one animation stack of an FBX file into a Motion.

    Parameters
    ----------
    path : str or path-like
        A binary or ASCII ``.fbx`` file (a ``bytes`` path is decoded with
        :func:`os.fsdecode`).
    take : str or int, optional
        The animation stack (take) to read, by name or by index in file
        order; default the first.
    fps : float, optional
        Frames per second to sample at; default the file's frame rate.
    skeleton : str, optional
        For a file with several skeletons: the name of the root joint of the
        one to read, or of a node above it (an armature).
    scale : float, optional
        Metres per file unit; default the unit the file states.
    name : str, optional
        Label for the motion (default: the file stem).

    Returns
    -------
    Motion
        ``rotations`` shape (F, J, 4), ``root_positions`` shape (F, 3) in
        metres, Y up; ``translations`` shape (F, J, 3) only when a joint's
        offset from its parent is animated.

    Raises
    ------
    MocapFormatError
        For any problem with the file (see the module notes), naming it.
    ValueError
        For a ``fps`` outside :data:`~mocaplab.motion.FPS_RANGE` or a
        ``scale`` that is not a positive finite number.
    TypeError
        For a ``path`` that is not a str, bytes or os.PathLike.

    Examples
    --------
    A CMU walk exported to FBX by Blender, from the mirror's ``fbx/`` folder:

    >>> from mocaplab.data import mirror_dir
    >>> walk = load_fbx(mirror_dir() / "fbx" / "16_15.fbx")
    >>> walk.n_frames, walk.fps, walk.skeleton.roles["pelvis"]
    (471, 120.0, 'Hips')
    """
    file = as_path(path)
    if fps is not None and not (
        isinstance(fps, (int, float, np.number)) and FPS_RANGE[0] <= float(fps) <= FPS_RANGE[1]
    ):
        raise ValueError(f"Expected `fps` from {FPS_RANGE[0]:g} to {FPS_RANGE[1]:g} frames per second, got {fps!r}")
    check_scale(scale)
    if take is not None and (isinstance(take, bool) or not isinstance(take, (str, int))):
        raise TypeError(f"Expected `take` to be a stack name or index, got {type(take).__name__}")
    raw = read_bytes(file, "an FBX file")
    _check_layout(file, raw)
    data = _read_scene(file, raw, {"take": take, "skeleton": skeleton, "fps": None if fps is None else float(fps)})
    unit = float(scale) if scale is not None else data["unit"]
    if not (math.isfinite(unit) and unit > 0):
        raise MocapFormatError(file, 0, "a positive UnitScaleFactor in GlobalSettings", f"{unit!r}")
    return motion_from_transforms(
        file,
        data["local"],
        data["rest"],
        data["parents"],
        inherit=data["inherit"],
        joints=data["joints"],
        names=data["names"],
        rotation_orders=data["rotation_orders"],
        fps=data["fps"],
        unit=unit,
        name=name,
    )


# ----------------------------------------------------------------- the bytes
def _check_layout(path: str, raw: bytes) -> None:
    """Reject bytes that are not FBX, and walk a binary file's records (truncation, array sizes)."""
    if raw.startswith(_BINARY_MAGIC):
        if len(raw) < 27:
            raise MocapFormatError(path, 0, "a complete FBX file (a 27-byte header)", f"{len(raw)} bytes (truncated)")
        version = struct.unpack_from("<I", raw, 23)[0]
        _walk_records(path, raw, 27, len(raw), version >= 7500, top=True)
        return
    head = raw[:4096].lstrip(b"\xef\xbb\xbf \t\r\n")
    if head.startswith(b";") or head.startswith(b"FBXHeaderExtension"):
        if b"FBX" in head:
            return
    shown = raw[:20]
    got = "an empty file" if not raw else f"bytes starting {shown!r}"
    raise MocapFormatError(path, 0, "an FBX file (binary, starting 'Kaydara FBX Binary', or ASCII FBX text)", got)


def _walk_records(path: str, raw: bytes, at: int, end: int, wide: bool, *, top: bool = False) -> int:
    """Check the node records from byte ``at`` to ``end``; return where the last one stops.

    A record is ``end offset, property count, property bytes, name length``
    (32-bit before FBX 7.5, 64-bit since), the name, the properties and the
    nested records; a record of zeros ends a list.
    """
    head = struct.Struct("<QQQB" if wide else "<IIIB")
    size = len(raw)
    while at + head.size <= end:
        stop, n_props, props_len, name_len = head.unpack_from(raw, at)
        if stop == 0:  # the null record closing a list (or the top-level footer)
            return at + head.size
        name = raw[at + head.size : at + head.size + name_len].decode("latin-1")
        if stop > size:
            raise MocapFormatError(
                path, 0, f"a complete FBX file ({stop:,} bytes: record {name!r} at byte {at:,} ends there)",
                f"{size:,} bytes (a truncated file)",
            )
        if stop <= at or stop > end:
            raise MocapFormatError(
                path, 0, f"FBX record {name!r} at byte {at:,} to end within its parent (by byte {end:,})",
                f"an end at byte {stop:,} (a corrupt file)",
            )
        p = at + head.size + name_len
        props_end = p + props_len
        if props_end > stop:
            raise MocapFormatError(
                path, 0, f"the properties of record {name!r} at byte {at:,} within the record",
                f"{props_len:,} bytes of properties (a corrupt file)",
            )
        for _ in range(n_props):
            p = _check_property(path, raw, p, props_end, name)
        if props_end < stop:
            _walk_records(path, raw, props_end, stop, wide)
        at = stop
    if top:
        return at
    if at != end:
        raise MocapFormatError(path, 0, f"nested FBX records to fill their parent up to byte {end:,}", f"byte {at:,}")
    return at


def _check_property(path: str, raw: bytes, p: int, end: int, record: str) -> int:
    """Check one property of ``record`` at byte ``p``; return where the next starts."""
    if p >= end:
        raise MocapFormatError(path, 0, f"another property in record {record!r}", "the end of its property list")
    code = raw[p]
    if code in _SCALAR_SIZES:
        nxt = p + 1 + _SCALAR_SIZES[code]
    elif code in (ord("S"), ord("R")):
        if p + 5 > end:
            raise MocapFormatError(path, 0, f"a string length in record {record!r}", "the end of the record")
        nxt = p + 5 + struct.unpack_from("<I", raw, p + 1)[0]
    elif code in _ARRAY_SIZES:
        if p + 13 > end:
            raise MocapFormatError(path, 0, f"an array header in record {record!r}", "the end of the record")
        count, encoding, stored = struct.unpack_from("<III", raw, p + 1)
        needed = count * _ARRAY_SIZES[code]
        if encoding == 0 and needed != stored or encoding == 1 and needed > MAX_DEFLATE_RATIO * stored:
            raise MocapFormatError(
                path, 0,
                f"an array in record {record!r} (byte {p:,}) whose {count:,} elements fit its {stored:,} stored bytes",
                f"{needed:,} bytes of elements (a corrupt file)",
            )
        if encoding not in (0, 1):
            raise MocapFormatError(path, 0, f"array encoding 0 or 1 in record {record!r}", f"{encoding}")
        nxt = p + 13 + stored
    else:
        raise MocapFormatError(
            path, 0, f"an FBX property type code in record {record!r} (byte {p:,})", f"{bytes([code])!r}"
        )
    if nxt > end:
        raise MocapFormatError(
            path, 0, f"the properties of record {record!r} to end within it", f"byte {nxt:,} past {end:,}"
        )
    return nxt


def _read_scene(path: str, raw: bytes, options: dict[str, Any]) -> dict[str, Any]:
    """Run the ufbx worker (``_ufbx_worker.py`` beside this file) on the file's bytes; its answer, or MocapFormatError."""
    request = dict(options, raw=raw, path=path, bounds=FPS_RANGE, unkeyed_frames=MAX_UNKEYED_FRAMES)
    try:
        done = subprocess.run(
            [sys.executable, os.path.join(os.path.dirname(os.path.abspath(__file__)), "_ufbx_worker.py")],
            input=pickle.dumps(request, protocol=pickle.HIGHEST_PROTOCOL),
            capture_output=True,
            check=False,
        )
    except OSError as exc:  # pragma: no cover - the interpreter itself cannot be started
        raise MocapFormatError(path, 0, "a running FBX reader process", f"{exc}") from exc
    try:
        answer = pickle.loads(done.stdout) if done.stdout else None
    except Exception:  # noqa: BLE001 - a worker cut short mid-answer
        answer = None
    if not isinstance(answer, tuple) or not answer:
        why = done.stderr.decode("utf-8", "replace").strip().splitlines()
        if done.returncode < 0:
            got = f"the ufbx reader stopped by signal {-done.returncode} while reading it"
        else:
            got = why[-1] if why else f"the ufbx reader ended with status {done.returncode}"
        if "No module named 'ufbx'" in got:
            raise ImportError("Reading FBX files needs the ufbx package: pip install ufbx") from None
        raise MocapFormatError(path, 0, "a file the ufbx reader can read", got)
    if answer[0] == "error":
        raise MocapFormatError(path, 0, answer[1], answer[2])
    data = answer[1]
    n, k = data["n_frames"], len(data["parents"])
    data["local"] = np.frombuffer(data["local"], dtype=np.float64).reshape(n, k, 10)
    data["rest"] = np.frombuffer(data["rest"], dtype=np.float64).reshape(1, k, 10)
    return data
