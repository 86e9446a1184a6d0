"""One entry point for every motion file: :func:`load`.

:func:`load` picks the reader from the file extension, then brings the motion
to the project's conventions (metres, Y up, see :mod:`mocaplab.motion`):

* **Unit.** As :func:`~mocaplab.io.load_bvh`: ``scale`` is metres per file
  unit, estimated from the skeleton size (with a ``UserWarning``) when not
  given.  ASF files state their unit, so nothing is estimated for them.
* **Frame rate.** BVH stores seconds per frame as text, often truncated
  (``Frame Time: 0.0333333`` is 30.0000003 fps).  A rate within a relative
  ``1e-5`` of an integer, or of an NTSC rate (24000/1001, 30000/1001 or
  60000/1001), is snapped to it exactly; any other rate is kept as read.
* **Up axis.** ``up="z"`` turns a Z-up file into Y-up by one rigid rotation
  of the whole motion, about +X by -90 degrees: ``(x, y, z) -> (x, z, -y)``.
* **Joint roles.** ``roles={"pelvis": "mixamorig:Hips", ...}`` names the
  joints whose role cannot be inferred from the names
  (:meth:`~mocaplab.motion.Skeleton.with_roles`).
"""

from __future__ import annotations

import dataclasses
import math
import os
import warnings
from collections.abc import Mapping
from os import PathLike
from pathlib import Path
from typing import Literal

import numpy as np

from .. import quat
from ..motion import Motion
from .bvh import load_bvh
from .errors import MocapFormatError

__all__ = ["load", "SUPPORTED_EXTENSIONS", "FPS_SNAP_TOLERANCE", "NTSC_RATES"]

#: File extensions :func:`load` reads (lowercase; matched case-insensitively).
SUPPORTED_EXTENSIONS: tuple[str, ...] = (".bvh", ".asf", ".amc", ".fbx", ".gltf", ".glb")

#: Relative distance within which a frame rate is snapped to a standard rate.
FPS_SNAP_TOLERANCE = 1e-5

#: Non-integer standard rates a frame rate may be snapped to (NTSC film, video, high rate).
NTSC_RATES: tuple[float, ...] = (24000 / 1001, 30000 / 1001, 60000 / 1001)

# The rigid rotation taking a Z-up file to Y-up: about +X by -90 degrees,
# (x, y, z) -> (x, z, -y), as an exact matrix (for points) and quaternion.
_Z_TO_Y_MATRIX = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
_Z_TO_Y_QUAT = np.array([-math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)])


def load(
    path: str | PathLike[str],
    *,
    scale: float | None = None,
    roles: Mapping[str, str] | None = None,
    up: Literal["y", "z"] = "y",
    name: str | None = None,
) -> Motion:
    """Read a motion file of any supported format into a Y-up Motion in metres.

    Parameters
    ----------
    path : str or path-like
        A ``.bvh`` file, an Acclaim ``.amc`` motion (its ``.asf`` skeleton is
        found beside it) or an ``.asf`` skeleton (with the one ``.amc`` in its
        folder).  The extension is matched case-insensitively.  For an
        ``.amc``, the skeleton is the first of: ``<prefix>.asf`` where
        ``<prefix>`` is the part of the AMC stem before its first ``_``
        (CMU: ``16_15.amc`` -> ``16.asf``), ``<stem>.asf``, the only ``.asf``
        in the folder.
    scale : float, optional
        Metres per file unit.  BVH: estimated from the skeleton size when
        omitted, with a ``UserWarning`` naming the unit assumed (see
        :func:`~mocaplab.io.estimate_scale`).  ASF: defaults to the unit the
        file states.
    roles : mapping of str to str, optional
        Role name -> joint name, for joints whose role the naming table does
        not recognise; applied with ``skeleton.with_roles(**roles)``.
    up : {"y", "z"}
        The file's up axis.  ``"z"`` rotates the whole motion about +X by
        -90 degrees, ``(x, y, z) -> (x, z, -y)``: root positions, the root
        joint's rotation (pre-multiplied) and the root's offset.  Offsets and
        local rotations of the other joints are unchanged.
    name : str, optional
        Label for the motion (default: the file stem; the AMC stem for
        Acclaim files).

    Returns
    -------
    Motion
        ``rotations`` shape (F, J, 4), ``root_positions`` shape (F, 3) in
        metres, Y up; ``fps`` snapped to a standard rate when the file's rate
        is within a relative ``1e-5`` of an integer or of 24000/1001,
        30000/1001 or 60000/1001 (``Frame Time: 0.0333333`` gives exactly
        30.0), otherwise ``1 / Frame Time`` as read.  Acclaim files carry no
        rate and get 120 fps (the CMU capture rate).

    Raises
    ------
    ValueError
        For an unsupported extension, an ``up`` other than ``"y"`` or
        ``"z"``, a bad ``scale``, or an ``.asf`` whose folder holds several
        ``.amc`` files (or an ``.amc`` next to several unrelated ``.asf``).
        :class:`~mocaplab.io.MocapFormatError` (a ``ValueError``) for a
        malformed file.
    MocapFormatError
        Also when the file, or the Acclaim file that goes with it, does not
        exist (every path problem is a MocapFormatError naming the path, as
        in the readers).
    TypeError
        For ``roles`` that is not a mapping.

    Examples
    --------
    >>> from mocaplab import load
    >>> walk = load("16_15.bvh")                        # doctest: +SKIP
    >>> same = load("subjects/16/16_15.amc")            # doctest: +SKIP
    >>> rig = load("char.bvh", up="z", scale=0.01)      # doctest: +SKIP
    >>> rig.fps                                         # doctest: +SKIP
    30.0
    """
    file = os.fspath(path)
    if up not in ("y", "z"):
        raise ValueError(f"Expected `up` to be 'y' or 'z' (the file's up axis), got {up!r}")
    if roles is not None and not isinstance(roles, Mapping):
        raise TypeError(
            f"Expected `roles` to be a mapping of role name to joint name (or None), got {type(roles).__name__}"
        )
    ext = os.path.splitext(file)[1].lower()
    if ext == ".bvh":
        motion = _load_bvh(file, scale=scale, name=name)
    elif ext in (".asf", ".amc"):
        from .asfamc import load_asf_amc

        asf, amc = (file, _amc_for(file)) if ext == ".asf" else (_asf_for(file), file)
        motion = load_asf_amc(asf, amc, scale=scale, name=name)
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
    if up == "z":
        motion = _z_up_to_y_up(motion)
    if roles:
        motion = motion.replace(skeleton=motion.skeleton.with_roles(**roles))
    return motion


def _load_bvh(file: str, *, scale: float | None, name: str | None) -> Motion:
    """:func:`load_bvh`, its unit warning re-issued so that it points at the caller of :func:`load`."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        motion = load_bvh(file, scale=scale, name=name)
    for w in caught:
        warnings.warn(w.message, stacklevel=3)  # 1: here, 2: load, 3: its caller
    return motion


def _snap_fps(fps: float) -> float:
    """``fps``, or the standard rate within a relative ``FPS_SNAP_TOLERANCE`` of it."""
    for rate in (float(round(fps)), *NTSC_RATES):
        if rate > 0 and abs(fps - rate) <= FPS_SNAP_TOLERANCE * rate:
            return rate
    return fps


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
    raise ValueError(
        f"{amc}: expected the .asf skeleton {tried} or a single .asf in {str(folder)!r}, "
        f"got {len(asfs)} others ({', '.join(a.name for a in asfs[:5])}); "
        "load it with mocaplab.io.load_asf_amc(asf_path, amc_path)"
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
