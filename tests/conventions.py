"""A CMU clip re-expressed in other skeleton conventions, as BVH files (test helpers).

Each converter takes a CMU :class:`~mocaplab.motion.Motion` (the 31 joints of
the CMU BVH conversions: ``Hips``, ``LHipJoint``, ``LeftUpLeg``, ...), writes
it to ``folder`` as a BVH file in another convention and returns
``(path, name_map)``: ``name_map[cmu_name]`` is the joint's name in the file.
Read back with ``mocaplab.load(path, **LOAD_OPTIONS.get(convention, {}))``,
every mapped joint has the CMU clip's global position (to file precision),
which is what ``test_conventions_io.py`` checks.  Each convention changes one
thing, so a failure points at one cause; all but ``centimetres`` keep the CMU
file unit (``0.0254 / 0.45`` m), which the loader's estimate must find.

=================  ==========================================================
``mixamo``         ``mixamorig:`` names, ``Zrotation Xrotation Yrotation``
``game_studio``    ``_L``/``_R`` names, a static ``joint_Root`` above the
                   translating ``Hips``, 6 channels on every joint
``asf_names``      the CMU Acclaim bone names (``root``, ``lfemur``, ...)
``centimetres``    CMU names, file in centimetres
``zero_end_sites`` every End Site offset zero
``x_bones``        bones along +X in the rest pose (rest rotations baked in)
``z_up``           the whole clip turned to Z up (read with ``up="z"``)
``fps30``          resampled to 30 fps, ``Frame Time: 0.0333333``
=================  ==========================================================

Joints a convention adds (not in ``name_map``, which maps CMU joints only) are
listed in :data:`EXTRA_JOINTS`.  No converter mutates its input (Motions are
frozen; new arrays are built).
"""

from __future__ import annotations

import dataclasses
import math
import re
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from mocaplab import Motion, Skeleton, quat, save_bvh
from mocaplab.io.asfamc import CMU_BVH_NAMES

#: Metres per unit of the CMU BVH files (the Acclaim unit, 1/0.45 inch).
CMU_UNIT_M = 0.0254 / 0.45

#: Options ``mocaplab.load`` needs for a convention (the others need none).
LOAD_OPTIONS: dict[str, dict[str, Any]] = {"z_up": {"up": "z"}}

#: Joints a convention adds that have no CMU counterpart, in file order.
EXTRA_JOINTS: dict[str, tuple[str, ...]] = {"game_studio": ("joint_Root",)}

SIX_CHANNELS = ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")


def _save(motion: Motion, folder: str | Path, convention: str, *, scale: float = CMU_UNIT_M) -> Path:
    path = Path(folder) / f"{motion.name or 'motion'}_{convention}.bvh"
    save_bvh(motion, path, scale=scale)
    return path


def _renamed(motion: Motion, name_map: dict[str, str], channels: tuple[tuple[str, ...], ...] | None = None) -> Motion:
    sk = motion.skeleton
    new = dataclasses.replace(
        sk, names=tuple(name_map[n] for n in sk.names), channels=sk.channels if channels is None else channels
    )
    return motion.replace(skeleton=new)


def _identity_map(motion: Motion) -> dict[str, str]:
    return {n: n for n in motion.skeleton.names}


# ------------------------------------------------------------------ names

#: CMU names onto the closest Mixamo names (before the ``mixamorig:`` prefix);
#: joints Mixamo lacks keep their CMU name.
MIXAMO_NAMES: dict[str, str] = {
    "LowerBack": "Spine",
    "Spine": "Spine1",
    "Spine1": "Spine2",
    "LThumb": "LeftHandThumb1",
    "RThumb": "RightHandThumb1",
}


def mixamo(motion: Motion, folder: str | Path) -> tuple[Path, dict[str, str]]:
    """Mixamo names (``mixamorig:Hips``, ``mixamorig:Spine``, ...) and Z-X-Y Euler channels.

    ``LowerBack``/``Spine``/``Spine1`` become ``Spine``/``Spine1``/``Spine2``
    and the thumbs ``LeftHandThumb1``/``RightHandThumb1``; joints Mixamo lacks
    keep their CMU name with the prefix (``mixamorig:LHipJoint``,
    ``mixamorig:Neck1``, ``mixamorig:LeftFingerBase``).  Rotation channels
    are ``Zrotation Xrotation Yrotation``, an order many exporters write.
    """
    name_map = {n: "mixamorig:" + MIXAMO_NAMES.get(n, n) for n in motion.skeleton.names}
    zxy = ("Zrotation", "Xrotation", "Yrotation")
    channels = (("Xposition", "Yposition", "Zposition") + zxy,) + (zxy,) * (motion.n_joints - 1)
    return _save(_renamed(motion, name_map, channels), folder, "mixamo"), name_map


#: CMU names in the ``_L``/``_R`` suffix style of game engines (one side; see ``_side``).
GAME_STUDIO_NAMES: dict[str, str] = {
    "Hips": "Hips",
    "LHipJoint": "HipOffset_L",
    "LeftUpLeg": "UpperLeg_L",
    "LeftLeg": "LowerLeg_L",
    "LeftFoot": "Foot_L",
    "LeftToeBase": "Toes_L",
    "LowerBack": "Spine_01",
    "Spine": "Spine_02",
    "Spine1": "Spine_03",
    "Neck": "Neck_01",
    "Neck1": "Neck_02",
    "Head": "Head",
    "LeftShoulder": "Clavicle_L",
    "LeftArm": "UpperArm_L",
    "LeftForeArm": "LowerArm_L",
    "LeftHand": "Hand_L",
    "LeftFingerBase": "Fingers_L",
    "LeftHandIndex1": "Index_L",
    "LThumb": "Thumb_L",
}


def _game_studio_name(cmu: str) -> str:
    if cmu in GAME_STUDIO_NAMES:
        return GAME_STUDIO_NAMES[cmu]
    left = cmu.replace("Right", "Left", 1) if "Right" in cmu else "L" + cmu[1:]  # RHipJoint, RThumb
    return GAME_STUDIO_NAMES[left][:-2] + "_R"


def game_studio(motion: Motion, folder: str | Path) -> tuple[Path, dict[str, str]]:
    """``_L``/``_R`` names under a static ``joint_Root``, 6 channels on every joint.

    Joint 0 is ``joint_Root``: zero position and identity rotation on every
    frame.  ``Hips`` is its child and carries the clip's translation through
    its own position channels (``Motion.translations``; its OFFSET is
    ``(0, first height, 0)``).  Every joint has ``Xposition Yposition Zposition
    Zrotation Yrotation Xrotation``; the other joints' position channels hold
    their constant offsets.  ``EXTRA_JOINTS["game_studio"]`` lists
    ``joint_Root``.
    """
    sk = motion.skeleton
    name_map = {n: _game_studio_name(n) for n in sk.names}
    n, frames = sk.n_joints + 1, motion.n_frames
    parents = np.concatenate([[-1, 0], sk.parents[1:] + 1])
    # the pelvis OFFSET: its first height above joint_Root (where engines put the rest pelvis)
    hips = np.array([[0.0, motion.root_positions[0, 1], 0.0]])
    offsets = np.concatenate([np.zeros((1, 3)), hips, sk.offsets[1:]])
    rotations = np.concatenate([quat.identity((frames, 1)), motion.rotations], axis=1)
    translations = np.empty((frames, n, 3))
    translations[:] = offsets
    translations[:, 1] = motion.root_positions
    if motion.translations is not None:
        translations[:, 2:] = motion.translations[:, 1:]
    skeleton = dataclasses.replace(
        sk,
        names=("joint_Root",) + tuple(name_map[x] for x in sk.names),
        parents=parents,
        offsets=offsets,
        channels=(SIX_CHANNELS,) * n,
        end_site_parents=sk.end_site_parents + 1,
    )
    out = Motion(skeleton, rotations, np.zeros((frames, 3)), motion.fps, translations=translations, name=motion.name)
    return _save(out, folder, "game_studio"), name_map


def static_root(m: Motion) -> Motion:
    """``m`` below a static ``joint_Root`` at the origin, in memory: the CMU names, the pelvis travel in ``translations``.

    The one change of a studio file's root layout (a static reference joint
    above the travelling pelvis, 6 channels on every joint), without the
    renaming of :func:`game_studio`: lesson code that names CMU joints runs
    on it unchanged (``tests/test_browser_laptop.py``).  Saved with
    ``save_bvh`` and read back with ``mocaplab.load``, it is a studio file.
    """
    sk = m.skeleton
    J, F = sk.n_joints, m.n_frames
    new = Skeleton(
        ("joint_Root",) + sk.names,
        np.r_[-1, np.asarray(sk.parents) + 1],
        np.vstack([np.zeros(3), sk.offsets]),
        channels=(sk.channels[0],) * (J + 1),
        end_site_parents=np.asarray(sk.end_site_parents) + 1,
        end_site_offsets=sk.end_site_offsets,
    )
    rot = np.concatenate([np.tile([0.0, 0.0, 0.0, 1.0], (F, 1, 1)), m.rotations], axis=1)
    tr = np.array(np.broadcast_to(new.offsets, (F, J + 1, 3)))
    tr[:, 1] = m.root_positions
    return Motion(new, rot, np.zeros((F, 3)), m.fps, translations=tr, name=m.name)


def read_clips_as_studio_files(folder: str | Path) -> None:
    """From now on, ``mocaplab.cmu`` (and ``mocaplab.data.cmu``) give each clip as a studio file: run a lesson on one.

    Each clip is written to ``folder`` below a static root (:func:`static_root`,
    in the CMU unit) and read back with ``mocaplab.load(path, scale=CMU_UNIT_M)``
    as a student reads their own file; its name stays the trial's.  For a
    kernel that runs lessons in a test (the browser tests), never for the
    test process itself: it replaces the functions in the modules.
    """
    import mocaplab
    import mocaplab.data
    from mocaplab import load

    original = mocaplab.data.cmu

    def studio_clip(trial: str, *args: Any, **kwargs: Any) -> Motion:
        clip = original(trial, *args, **kwargs)
        path = Path(folder) / f"{clip.name or trial}_static_root.bvh"
        save_bvh(static_root(clip), path, scale=CMU_UNIT_M)
        return load(path, scale=CMU_UNIT_M, name=clip.name)

    mocaplab.data.cmu = studio_clip
    mocaplab.cmu = studio_clip  # type: ignore[attr-defined]


#: The first cell of a lesson run on studio files: in that kernel, every CMU clip is read as one
#: (:func:`read_clips_as_studio_files`, in a fresh temporary folder).
STUDIO_CELL = f"""\
import sys as _sys, tempfile as _tempfile
_sys.path.insert(0, {str(Path(__file__).resolve().parent)!r})
from conventions import read_clips_as_studio_files
read_clips_as_studio_files(_tempfile.mkdtemp(prefix="studio_files_"))  # every clip as a file with a static root
"""


def asf_names(motion: Motion, folder: str | Path) -> tuple[Path, dict[str, str]]:
    """The CMU Acclaim bone names (``root``, ``lhipjoint``, ``lfemur``, ...) written as BVH."""
    to_asf = {bvh: asf for asf, bvh in CMU_BVH_NAMES.items()}
    name_map = {n: to_asf[n] for n in motion.skeleton.names}
    return _save(_renamed(motion, name_map), folder, "asf_names"), name_map


# ----------------------------------------------------------------- units


def centimetres(motion: Motion, folder: str | Path) -> tuple[Path, dict[str, str]]:
    """CMU names, every length in centimetres (metres x 100: offsets, end sites, positions)."""
    return _save(motion, folder, "centimetres", scale=0.01), _identity_map(motion)


def zero_end_sites(motion: Motion, folder: str | Path) -> tuple[Path, dict[str, str]]:
    """Every End Site offset zero (each end site sits on its joint)."""
    sk = motion.skeleton
    skeleton = dataclasses.replace(sk, end_site_offsets=np.zeros_like(sk.end_site_offsets))
    return _save(motion.replace(skeleton=skeleton), folder, "zero_end_sites"), _identity_map(motion)


# ------------------------------------------------------------- rest pose


def x_bones(motion: Motion, folder: str | Path) -> tuple[Path, dict[str, str]]:
    """Bones along +X in the rest pose, the rest rotations baked into the motion.

    Joint ``j`` gets a constant correction ``C_j``: the rotation taking +X
    onto its first child's offset (identity without a child or for a zero
    offset).  Offsets become ``C_p^-1 o_c`` (the first child's is
    ``(|o|, 0, 0)``), end sites ``C_j^-1 e``, local rotations
    ``C_parent^-1 L_j C_j`` (root: ``L_0 C_0``), so every global rotation is
    ``G_j C_j`` and every global position is unchanged.  The rest pose (all
    rotations identity) is a degenerate zig-zag.
    """
    sk = motion.skeleton
    n = sk.n_joints
    correction = quat.identity((n,))
    for j in range(n):
        kids = sk.children(j)
        if kids and np.linalg.norm(sk.offsets[kids[0]]) > 0:
            correction[j] = quat.between(np.array([1.0, 0.0, 0.0]), sk.offsets[kids[0]])
    undo = quat.inv(correction)
    p = sk.parents[1:]
    offsets = np.array(sk.offsets, copy=True)
    offsets[1:] = quat.rotate(undo[p], sk.offsets[1:])
    rotations = np.empty_like(motion.rotations)
    rotations[:, 0] = quat.mul(motion.rotations[:, 0], correction[0])
    rotations[:, 1:] = quat.mul(quat.mul(undo[p], motion.rotations[:, 1:]), correction[1:])
    translations = None
    if motion.translations is not None:
        translations = np.array(motion.translations, copy=True)
        translations[:, 1:] = quat.rotate(undo[p], motion.translations[:, 1:])
    skeleton = dataclasses.replace(
        sk, offsets=offsets, end_site_offsets=quat.rotate(undo[sk.end_site_parents], sk.end_site_offsets)
    )
    out = motion.replace(skeleton=skeleton, rotations=rotations, translations=translations)
    return _save(out, folder, "x_bones"), _identity_map(motion)


# ----------------------------------------------------------- axes, time

# Y up -> Z up: about +X by +90 degrees, (x, y, z) -> (x, -z, y); the inverse of
# mocaplab.load(..., up="z").  Written here independently of the loader.
_Y_TO_Z_MATRIX = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
_Y_TO_Z_QUAT = np.array([math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)])


def z_up(motion: Motion, folder: str | Path) -> tuple[Path, dict[str, str]]:
    """The whole clip turned rigidly to Z up, ``(x, y, z) -> (x, -z, y)`` (load with ``up="z"``).

    Root positions, the root rotation (pre-multiplied) and the root offset
    turn; the other joints' offsets and local rotations are unchanged.
    """
    sk = motion.skeleton
    offsets = np.array(sk.offsets, copy=True)
    offsets[0] = _Y_TO_Z_MATRIX @ sk.offsets[0]
    rotations = np.array(motion.rotations, copy=True)
    rotations[:, 0] = quat.mul(_Y_TO_Z_QUAT, motion.rotations[:, 0])
    out = motion.replace(
        skeleton=dataclasses.replace(sk, offsets=offsets),
        rotations=rotations,
        root_positions=motion.root_positions @ _Y_TO_Z_MATRIX.T,
    )
    return _save(out, folder, "z_up"), _identity_map(motion)


def fps30(motion: Motion, folder: str | Path) -> tuple[Path, dict[str, str]]:
    """Resampled to 30 fps, the Frame Time truncated to ``0.0333333`` as many exporters write it.

    Compare with ``motion.resample(30.0)``; the loader must snap the rate to
    exactly 30.0.
    """
    path = _save(motion.resample(30.0), folder, "fps30")
    text, count = re.subn(r"(?m)^Frame Time:.*$", "Frame Time: 0.0333333", path.read_text())
    if count != 1:
        raise RuntimeError(f"{path}: expected one 'Frame Time:' line, got {count}")
    path.write_text(text)
    return path, _identity_map(motion)


CONVERTERS: dict[str, Callable[[Motion, str | Path], tuple[Path, dict[str, str]]]] = {
    "mixamo": mixamo,
    "game_studio": game_studio,
    "asf_names": asf_names,
    "centimetres": centimetres,
    "zero_end_sites": zero_end_sites,
    "x_bones": x_bones,
    "z_up": z_up,
    "fps30": fps30,
}

#: Every convention name, in the order above.
CONVENTIONS: list[str] = list(CONVERTERS)


def convert(motion: Motion, convention: str, folder: str | Path) -> tuple[Path, dict[str, str]]:
    """Write ``motion`` to ``folder`` in ``convention`` (one of :data:`CONVENTIONS`)."""
    try:
        converter = CONVERTERS[convention]
    except KeyError:
        raise ValueError(f"Expected `convention` to be one of {CONVENTIONS}, got {convention!r}") from None
    return converter(motion, folder)


def load_converted(motion: Motion, convention: str, folder: str | Path) -> tuple[Motion, dict[str, str]]:
    """Write ``motion`` in ``convention`` to ``folder`` and read it back with :func:`mocaplab.load`.

    Warnings the loader gives on purpose (the estimated unit, the path joint)
    are silenced.  Returns ``(loaded motion, name_map)``.
    """
    from mocaplab import load

    path, name_map = convert(motion, convention, folder)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        loaded = load(path, **LOAD_OPTIONS.get(convention, {}))
    return loaded, name_map


def as_original(motion: Motion, convention: str) -> Motion:
    """The CMU motion a converted file should match (``fps30`` files are resampled)."""
    return motion.resample(30.0) if convention == "fps30" else motion
