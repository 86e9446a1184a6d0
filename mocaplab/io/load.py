"""One entry point for every motion file: :func:`load`.

:func:`load` picks the reader from the file extension, then brings the motion
to the project's conventions (metres, Y up, see :mod:`mocaplab.motion`):

* **Unit.** As :func:`~mocaplab.io.load_bvh`: ``scale`` is metres per file
  unit, estimated from the skeleton size (with a ``UserWarning``) when not
  given.  ASF files state their unit, so nothing is estimated for them.
* **Frame rate.** BVH stores seconds per frame as text, rounded to a few
  digits (``Frame Time: 0.033333`` is 30.0003 fps).  The rate is snapped to
  a common rate (:data:`COMMON_RATES`) when the written period is that
  rate's period rounded to the significant digits written (at least three),
  and no other common rate rounds to the same text; also when it lies within
  a relative ``1e-5`` of an integer or an NTSC rate (the earlier rule).  Any
  other rate is kept as read.  See :func:`snap_fps`.
* **Up axis.** Found from the body when the file does not say
  (:func:`find_up_axis`: the pelvis-to-head and feet-to-pelvis directions
  over the motion's frames): a file standing along +Z is turned to Y up,
  with a ``UserWarning`` naming the axis.  ``up="y"`` or ``up="z"`` says it
  and skips the search; ``"z"`` turns the whole motion by one rigid
  rotation about +X by -90 degrees: ``(x, y, z) -> (x, z, -y)``.
* **Skeleton of an Acclaim motion.** ``asf=`` names it when the folder
  holds several ``.asf`` files.
* **Joint roles.** ``roles={"pelvis": "mixamorig:Hips", ...}`` names the
  joints whose role cannot be inferred from the names
  (:meth:`~mocaplab.motion.Skeleton.with_roles`).
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping
from os import PathLike
from pathlib import Path
from typing import Literal

import numpy as np

from .. import quat
from .._warnings import warn
from ..motion import Motion
from ..roles import RolesError
from .bvh import as_path, check_scale, load_bvh
from .errors import MocapFormatError

__all__ = [
    "load",
    "snap_fps",
    "find_up_axis",
    "SUPPORTED_EXTENSIONS",
    "FPS_SNAP_TOLERANCE",
    "NTSC_RATES",
    "COMMON_RATES",
    "UP_AXIS_AGREEMENT",
]

#: File extensions :func:`load` reads (lowercase; matched case-insensitively).
SUPPORTED_EXTENSIONS: tuple[str, ...] = (".bvh", ".asf", ".amc", ".fbx", ".gltf", ".glb")

#: Relative distance within which a frame rate is snapped to a standard rate.
FPS_SNAP_TOLERANCE = 1e-5

#: Non-integer standard rates a frame rate may be snapped to (NTSC film, video, high rate).
NTSC_RATES: tuple[float, ...] = (24000 / 1001, 30000 / 1001, 60000 / 1001)

#: Frame rates of cameras, film, video and motion-capture systems that a
#: rounded ``Frame Time`` is snapped to (:func:`snap_fps`), frames per second.
COMMON_RATES: tuple[float, ...] = (
    10.0, 12.0, 15.0, 20.0, 24000 / 1001, 24.0, 25.0, 30000 / 1001, 30.0, 40.0, 48.0, 50.0, 60000 / 1001, 60.0,
    72.0, 90.0, 100.0, 120.0, 144.0, 150.0, 180.0, 200.0, 240.0, 250.0, 300.0, 360.0, 480.0, 500.0, 960.0, 1000.0,
)

#: Least component, along the chosen axis, of the body's mean up direction
#: (a unit vector) for :func:`find_up_axis` to decide (about 37 degrees).
UP_AXIS_AGREEMENT = 0.8

#: Most frames :func:`find_up_axis` measures (evenly spaced over the clip).
_UP_SAMPLE = 240

# The rigid rotation taking a Z-up file to Y-up: about +X by -90 degrees,
# (x, y, z) -> (x, z, -y), as an exact matrix (for points) and quaternion.
_Z_TO_Y_MATRIX = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
_Z_TO_Y_QUAT = np.array([-math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)])


def load(
    path: str | PathLike[str],
    *,
    scale: float | None = None,
    roles: Mapping[str, str] | None = None,
    up: Literal["y", "z"] | None = None,
    name: str | None = None,
    asf: str | PathLike[str] | None = None,
) -> Motion:
    """Read a motion file of any supported format into a Y-up Motion in metres.

    Parameters
    ----------
    path : str or path-like
        A ``.bvh`` file, an Acclaim ``.amc`` motion (its ``.asf`` skeleton is
        found beside it, or given as ``asf=``) or an ``.asf`` skeleton (with
        the one ``.amc`` in its folder).  The extension is matched
        case-insensitively.  For an ``.amc`` without ``asf=``, the skeleton
        is the first of: ``<prefix>.asf`` where ``<prefix>`` is the part of
        the AMC stem before its first ``_`` (CMU: ``16_15.amc`` ->
        ``16.asf``), ``<stem>.asf``, the only ``.asf`` in the folder.
    scale : float, optional
        Metres per file unit.  BVH: estimated from the skeleton size when
        omitted, with a ``UserWarning`` naming the unit assumed (see
        :func:`~mocaplab.io.estimate_scale`).  ASF: defaults to the unit the
        file states.
    roles : mapping of str to str, optional
        Role name -> joint name, for joints whose role the naming table does
        not recognise; applied with ``skeleton.with_roles(**roles)`` (and
        used to find the up axis).
    up : {"y", "z"}, optional
        The file's up axis.  Omitted: found from the body
        (:func:`find_up_axis`); a body standing along +Z is turned to Y up
        with a ``UserWarning`` naming the axis, and a body standing along
        another axis (X, or upside down) is kept as read with a warning.
        ``"z"`` rotates the whole motion about +X by -90 degrees,
        ``(x, y, z) -> (x, z, -y)``: root positions, the root joint's
        rotation (pre-multiplied) and the root's offset.  Offsets and local
        rotations of the other joints are unchanged.  ``"y"`` keeps the
        motion as read.
    name : str, optional
        Label for the motion (default: the file stem; the AMC stem for
        Acclaim files).
    asf : str or path-like, optional
        The ASF skeleton of an ``.amc`` ``path`` (when its folder holds
        several and none is named after the motion).

    Returns
    -------
    Motion
        ``rotations`` shape (F, J, 4), ``root_positions`` shape (F, 3) in
        metres, Y up; ``fps`` snapped to a common rate as :func:`snap_fps`
        says (``Frame Time: 0.033333`` and ``0.0333333`` both give exactly
        30.0), otherwise ``1 / Frame Time`` as read.  Acclaim files carry no
        rate and get 120 fps (the CMU capture rate).

    Raises
    ------
    ValueError
        For an unsupported extension, an ``up`` other than ``"y"``, ``"z"``
        or None, a bad ``scale``, ``asf=`` with a path that is not an
        ``.amc``, or an ``.asf`` whose folder holds several ``.amc`` files
        (or an ``.amc`` next to several unrelated ``.asf``: the message
        lists them; pass ``asf=``).
        :class:`~mocaplab.io.MocapFormatError` (a ``ValueError``) for a
        malformed file.
    MocapFormatError
        Also when the file, or the Acclaim file that goes with it, does not
        exist (every path problem is a MocapFormatError naming the path, as
        in the readers).
    TypeError
        For ``roles`` that is not a mapping, or an ``asf`` that is not a path.

    Examples
    --------
    The same CMU walk from its BVH file and from its ASF/AMC pair (found
    beside the ``.amc``), in the mirror (``MOCAPLAB_DATA_DIR``):

    >>> from mocaplab import load
    >>> from mocaplab.data import mirror_dir
    >>> walk = load(mirror_dir() / "bvh" / "16_15.bvh", scale=0.0254 / 0.45)
    >>> same = load(mirror_dir() / "asfamc" / "16" / "16_15.amc")
    >>> walk.fps, walk.n_frames, same.n_frames
    (120.0, 471, 471)

    Other files name their Acclaim skeleton or their axes and unit:
    ``load("takes/walk.amc", asf="takes/actor2.asf")``,
    ``load("char.bvh", up="z", scale=0.01)``.
    """
    file = os.fspath(path)
    if up not in ("y", "z", None):
        raise ValueError(
            f"Expected `up` to be 'y' or 'z' (the file's up axis) or None (found from the body), got {up!r}"
        )
    if roles is not None and not isinstance(roles, Mapping):
        raise TypeError(
            f"Expected `roles` to be a mapping of role name to joint name (or None), got {type(roles).__name__}"
        )
    check_scale(scale)
    ext = os.path.splitext(file)[1].lower()
    if asf is not None and ext != ".amc":
        raise ValueError(f"Expected `asf` only with an .amc motion (it names that motion's skeleton), got {file!r}")
    if ext == ".bvh":
        motion = load_bvh(file, scale=scale, name=name)
    elif ext in (".asf", ".amc"):
        from .asfamc import load_asf_amc

        if asf is not None:
            skeleton = as_path(asf, "asf")  # read (and any path problem reported) by load_asf_amc
        else:
            skeleton = file if ext == ".asf" else _asf_for(file)
        motion = load_asf_amc(skeleton, _amc_for(file) if ext == ".asf" else file, scale=scale, name=name)
    elif ext == ".fbx":  # units and axes from the file (take=, fps=, skeleton=: mocaplab.io.load_fbx)
        from .fbx import load_fbx

        motion = load_fbx(file, scale=scale, name=name)
    elif ext in (".gltf", ".glb"):  # metres and Y up by definition (animation=, fps=: mocaplab.io.load_gltf)
        from .gltf import load_gltf

        if scale is not None:
            raise ValueError(f"Expected no `scale` for a glTF file (glTF is in metres), got {scale!r}")
        motion = load_gltf(file, name=name)
    else:
        raise ValueError(
            f"Expected `path` to end in one of {', '.join(SUPPORTED_EXTENSIONS)} (case-insensitive), "
            f"got {file!r}"
        )
    fps = _snap_fps(motion.fps)
    if fps != motion.fps:
        motion = motion.replace(fps=fps)
    if up is None:
        found = find_up_axis(motion, roles=roles)
        if found == "+z":
            warn(
                f"{file}: the body stands along +Z (pelvis to head, feet to pelvis), so the file was read as Z up "
                "and turned to Y up. Pass up='z' to say so, or up='y' to keep the file's axes",
                UserWarning,
            )
            up = "z"
        elif found is not None and found != "+y":
            warn(
                f"{file}: the body stands along {found.upper()} (pelvis to head, feet to pelvis), not +Y or +Z; "
                "it is kept as read. Pass up='y' to silence this",
                UserWarning,
            )
    if up == "z":
        motion = _z_up_to_y_up(motion)
    if roles:
        motion = motion.replace(skeleton=motion.skeleton.with_roles(**roles))
    return motion


def snap_fps(fps: float) -> float:
    """The common frame rate a rate read from a file stands for, or the rate itself.

    BVH files store seconds per frame, rounded to the digits the exporter
    wrote (``Frame Time: 0.033333`` is 30.0003 fps as read).  The rule:

    1. A rate within a relative :data:`FPS_SNAP_TOLERANCE` (``1e-5``) of an
       integer or of an NTSC rate (:data:`NTSC_RATES`) is that rate.
    2. Otherwise, with ``T = 1 / fps`` the period as written: for ``d`` from
       3 to 15 significant digits, the common rates (:data:`COMMON_RATES`)
       whose period rounded to ``d`` significant digits equals ``T`` are
       found; at the first ``d`` where any is found, a single one is the
       rate, and two or more (the digits written cannot tell 24 from
       24000/1001 in ``0.0417``) leave the rate as read.
    3. Otherwise the rate is kept as read.

    So a period is snapped only when it is exactly what an exporter writing
    ``d`` digits would write for that rate: ``0.033333``, ``0.0333333`` and
    ``0.03333333`` give 30, ``0.008333`` gives 120; ``0.03336`` (29.976, near
    neither 30 nor 30000/1001 at five digits), ``0.016666`` (60 truncated,
    not rounded) and ``0.03`` (one digit) stay as read.

    Parameters
    ----------
    fps : float
        Frames per second as read (``1 / Frame Time``).

    Returns
    -------
    float

    Examples
    --------
    >>> snap_fps(1 / 0.033333), snap_fps(1 / 0.0417083), snap_fps(1 / 0.03336) == 1 / 0.03336
    (30.0, 23.976023976023978, True)
    """
    for rate in (float(round(fps)), *NTSC_RATES):
        if rate > 0 and abs(fps - rate) <= FPS_SNAP_TOLERANCE * rate:
            return rate
    period = 1.0 / fps
    for digits in range(3, 16):
        hits = [r for r in COMMON_RATES if abs(float(f"{1.0 / r:.{digits}g}") - period) <= 1e-12 * period]
        if hits:
            return float(hits[0]) if len(hits) == 1 else fps
    return fps


_snap_fps = snap_fps  # the name the loader calls (tests switch it off through it)


def find_up_axis(motion: Motion, *, roles: Mapping[str, str] | None = None) -> str | None:
    """The axis the body stands along in a motion as read: ``"+y"``, ``"+z"``, ``"-y"``, ... or None.

    Two directions of the body are measured on up to 240 frames spread
    evenly over the clip, as unit vectors: from the pelvis to the head (or
    the neck) and from the mean of the ankles to the pelvis (those the
    skeleton has roles for).  Their means over the frames are added and
    normalised; the signed axis with the largest component of that
    direction is the answer when the component is at least
    :data:`UP_AXIS_AGREEMENT` (the body stands within about 37 degrees of
    the axis on average).  The motion, not the rest pose, is measured: a
    file whose skeleton is built Y up but whose root rotation lays every
    frame Z up stands along Z.

    Parameters
    ----------
    motion : Motion
        As read from the file (before any change of axes).
    roles : mapping of str to str, optional
        Role overrides, as ``load(..., roles=...)`` takes them.

    Returns
    -------
    str or None
        None when the roles give neither a head/neck nor ankles with the
        pelvis (or the skeleton is not a biped), or the body does not
        stand clearly along one axis.  A clip of someone lying down for its
        whole length stands along the floor: pass ``up=`` to ``load``.

    Examples
    --------
    >>> find_up_axis(load("bvh_test1.bvh", up="y"))  # doctest: +SKIP
    '+z'
    """
    from ..roles import _infer

    sk = motion.skeleton
    try:
        r = _infer(sk, overrides=dict(sk.role_overrides) | dict(roles or {}))
    except RolesError:
        return None
    if "pelvis" not in r:
        return None
    top = r.get("head", r.get("neck"))
    ankles = [r.index(f"{s}_ankle") for s in ("left", "right") if f"{s}_ankle" in r]
    if top is None and not ankles:
        return None
    step = max(1, -(-motion.n_frames // _UP_SAMPLE))
    frames = slice(0, None, step)
    sample = motion.replace(
        rotations=motion.rotations[frames],
        root_positions=motion.root_positions[frames],
        translations=None if motion.translations is None else motion.translations[frames],
    )
    g = sample.global_positions()
    pelvis = g[:, r.index("pelvis")]
    parts = []
    if top is not None:
        parts.append(g[:, sk.index(top)] - pelvis)
    if ankles:
        parts.append(pelvis - g[:, ankles].mean(axis=1))
    up = np.zeros(3)
    for v in parts:
        length = np.linalg.norm(v, axis=-1, keepdims=True)
        unit = np.divide(v, length, out=np.zeros_like(v), where=length > 0)
        up += unit.mean(axis=0)
    norm = float(np.linalg.norm(up))
    if not norm > 0:
        return None
    up /= norm
    axis = int(np.argmax(np.abs(up)))
    if abs(up[axis]) < UP_AXIS_AGREEMENT:
        return None
    return ("+" if up[axis] > 0 else "-") + "xyz"[axis]


def _z_up_to_y_up(motion: Motion) -> Motion:
    """The motion turned rigidly about +X by -90 degrees: ``(x, y, z) -> (x, z, -y)``."""
    sk = motion.skeleton
    offsets = np.array(sk.offsets, copy=True)
    offsets[0] = _Z_TO_Y_MATRIX @ offsets[0]
    rotations = np.array(motion.rotations, copy=True)
    rotations[:, 0] = quat.mul(_Z_TO_Y_QUAT, motion.rotations[:, 0])
    translations = None
    if motion.translations is not None:
        # the root row is not used by forward kinematics; keep it the root offset
        translations = np.array(motion.translations, copy=True)
        translations[:, 0] = offsets[0]
    return motion.replace(
        skeleton=dataclasses.replace(sk, offsets=offsets),
        rotations=rotations,
        root_positions=motion.root_positions @ _Z_TO_Y_MATRIX.T,
        translations=translations,
    )


def _folder_files(folder: Path, ext: str) -> list[Path]:
    """Files in ``folder`` with extension ``ext`` (any case), sorted by name."""
    try:
        entries = list(folder.iterdir())
    except OSError:
        return []
    return sorted(p for p in entries if p.suffix.lower() == ext and p.is_file())


def _asf_for(amc: str) -> str:
    """The ASF skeleton that goes with the AMC motion ``amc``."""
    p = Path(amc)
    folder = p.parent
    if not p.is_file():
        raise MocapFormatError(amc, 0, "an AMC file", "no such file")
    asfs = _folder_files(folder, ".asf")
    by_stem = {a.stem: a for a in asfs}
    wanted = [p.stem.split("_", 1)[0]] if "_" in p.stem else []
    wanted.append(p.stem)
    for stem in wanted:
        if stem in by_stem:
            return str(by_stem[stem])
    if len(asfs) == 1:
        return str(asfs[0])
    tried = " or ".join(f"{s}.asf" for s in wanted)
    if not asfs:
        raise MocapFormatError(
            amc, 0, f"an .asf skeleton beside the .amc motion ({tried} or the only .asf in {str(folder)!r})",
            "no .asf file there; put the skeleton next to the motion",
        )
    shown = ", ".join(a.name for a in asfs[:10]) + (", ..." if len(asfs) > 10 else "")
    raise ValueError(
        f"{amc}: expected the .asf skeleton {tried} or a single .asf in {str(folder)!r}, "
        f"got {len(asfs)} others ({shown}); say which with asf=, e.g. "
        f"load({amc!r}, asf={str(asfs[0])!r})"
    )


def _amc_for(asf: str) -> str:
    """The one AMC motion in the folder of the ASF skeleton ``asf``."""
    p = Path(asf)
    if not p.is_file():
        raise MocapFormatError(asf, 0, "an ASF file", "no such file")
    amcs = _folder_files(p.parent, ".amc")
    if len(amcs) == 1:
        return str(amcs[0])
    if not amcs:
        raise MocapFormatError(
            asf, 0, f"one .amc motion in {str(p.parent)!r} (an .asf holds only a skeleton)", "none"
        )
    raise ValueError(
        f"{asf}: an .asf holds only a skeleton; expected one .amc motion in {str(p.parent)!r}, got "
        f"{len(amcs)} ({', '.join(a.name for a in amcs[:5])}{', ...' if len(amcs) > 5 else ''}); "
        "pass the .amc path instead, e.g. load(" + repr(str(amcs[0])) + ")"
    )
