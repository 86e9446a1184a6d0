"""The motion data model: :class:`Skeleton` and :class:`Motion`.

Conventions, written once for the whole package
-----------------------------------------------
* **Units:** metres and seconds; angles inside the core are radians (degrees
  appear only in file formats).
* **Axes:** right-handed, **Y up**, the ground is the plane ``y = 0``.  The
  ground plane coordinates of a point are ``(x, z)``.
* **Quaternions:** ``(x, y, z, w)``, scalar last, as in
  :mod:`scipy.spatial.transform` (see :mod:`mocaplab.quat`).
* **Frames and time:** frame ``i`` of a clip sampled at ``fps`` frames per
  second happens at time ``i / fps`` seconds after its first frame.
* **Joints:** joint 0 is the root; ``parents[j] < j`` for every other joint,
  so a single forward pass visits parents before children.  A joint argument
  is a name or an index (:meth:`Skeleton.index` resolves both).
* **Frame intervals** are half-open ``(start, stop)`` pairs, like Python
  slices: frames ``start .. stop - 1``.  Contacts, goals, end effectors,
  stationary segments and the editing constraints' ``frames=`` all use it;
  both ends included is accepted only under its own name
  (``frames_inclusive=(first, last)`` of :mod:`mocaplab.editing`).

Both classes are frozen dataclasses whose arrays are private, read-only
copies: no function in mocaplab mutates a Motion, every operation returns a
new one.

Longer than 800 lines because it holds the package's conventions, written once, beside the two classes every module uses and their examples.
"""

from __future__ import annotations

import dataclasses
import io
import sys
from collections.abc import Sequence
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import kinematics, quat
from ._warnings import warn
from .roles import Roles, RolesError, infer_roles, mirror_map

__all__ = ["Skeleton", "Motion", "concatenate", "readonly", "FPS_RANGE"]

DEFAULT_ROOT_CHANNELS = ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")
DEFAULT_JOINT_CHANNELS = ("Zrotation", "Yrotation", "Xrotation")
#: Frame rates a Motion may have (frames per second, inclusive): below 0.1 fps
#: or above 10,000 fps a clip is almost surely a unit mistake, and kernels sized
#: in frames (smoothing, blending windows) would be absurd; the file readers
#: reject such files at their frame-time line.
FPS_RANGE: tuple[float, float] = (0.1, 10000.0)

VALID_CHANNELS = frozenset(
    ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")
)


def readonly(arr: ArrayLike) -> NDArray[Any]:
    """A read-only array with the values of ``arr`` that can never be made writeable.

    The values are copied once into an immutable ``bytes`` object and the
    array returned is a view of it: numpy refuses ``flags.writeable = True``
    on it and on every array reachable through ``.base`` (a read-only array
    that owned its memory could be switched back).  An array frozen this way
    already is returned as a new read-only view, without a copy, so frozen
    objects share frozen data freely.  ``arr`` itself is left as it is.

    Parameters
    ----------
    arr : array_like
        Any array (object arrays are copied and flagged read-only only).

    Returns
    -------
    ndarray
        Same shape and dtype as ``arr``.

    Examples
    --------
    >>> import numpy as np
    >>> a = readonly(np.zeros(3))
    >>> a.base.flags.writeable = True
    Traceback (most recent call last):
    ...
    ValueError: cannot set WRITEABLE flag to True of this array
    """
    arr = np.asarray(arr)
    owner = arr
    while isinstance(owner.base, np.ndarray):
        owner = owner.base
    if isinstance(owner.base, bytes):  # frozen for good already: share it
        view = arr.view()
        view.flags.writeable = False
        return view
    if arr.dtype.hasobject:  # no buffer to freeze: a private copy, flagged read-only
        copy = np.array(arr, copy=True)
        copy.flags.writeable = False
        view = copy.view()
        view.flags.writeable = False
        return view
    frozen = np.frombuffer(arr.tobytes(order="C"), dtype=arr.dtype).reshape(arr.shape)
    frozen.flags.writeable = False
    return frozen


class _Fresh:
    """A new writable array whose memory becomes immutable, without a copy, when frozen.

    For readers that fill a large array in place: ``buf = _Fresh(shape)``,
    write ``buf.array``, drop every other reference to it, then
    ``buf.freeze()`` returns the same memory as a read-only array that can
    never be made writeable (a ``bytes`` object owns it, as with
    :func:`readonly`), so the result is not copied.  If views of
    ``buf.array`` are still alive when it is frozen, the values are copied
    instead (those views must not see the frozen data change).
    """

    __slots__ = ("array", "_buffer", "_view")

    def __init__(self, shape: tuple[int, ...], dtype: Any = float):
        dtype = np.dtype(dtype)
        size = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
        self._buffer = io.BytesIO()
        if size:
            self._buffer.seek(size - 1)
            self._buffer.write(b"\0")
        self._view: memoryview | None = self._buffer.getbuffer()
        self.array: NDArray[Any] = np.frombuffer(self._view, dtype=dtype).reshape(shape)

    def freeze(self) -> NDArray[Any]:
        """The values, read-only for good (no copy when nothing else sees ``array``)."""
        if self._view is None:
            raise RuntimeError("This array was frozen already")
        shape, dtype = self.array.shape, self.array.dtype
        del self.array  # gone from here on (an AttributeError)
        view, self._view = self._view, None
        if sys.getrefcount(view) <= 2:  # this name and the call's argument: no array left on the buffer
            view.release()  # the buffer is then handed over as it is, not copied
        data = self._buffer.getvalue()
        del view
        frozen = np.frombuffer(data, dtype=dtype).reshape(shape)
        frozen.flags.writeable = False
        return frozen


def _check_fps(fps: Any) -> float:
    # a real number: not a string ("30" reads, "3O" fails far away), not a bool
    if isinstance(fps, (bool, np.bool_)) or not isinstance(fps, (int, float, np.integer, np.floating)):
        raise ValueError(f"Expected `fps` to be a number of frames per second, got {type(fps).__name__} {fps!r}")
    value = float(fps)
    if not FPS_RANGE[0] <= value <= FPS_RANGE[1]:
        raise ValueError(
            f"Expected `fps` from {FPS_RANGE[0]:g} to {FPS_RANGE[1]:g} frames per second, got {fps!r}"
        )
    return value


def _frozen(a: ArrayLike, dtype: Any = float) -> NDArray[Any]:
    return readonly(np.asarray(a, dtype=dtype))


class _Owned:
    """A freshly built array handed to a constructor without a defensive copy.

    Only for code inside mocaplab that builds an array, passes it as
    ``_owned(array)`` and keeps no other reference to it: the constructor
    validates it as usual and freezes it (:func:`readonly`, one copy into
    immutable memory) without a defensive copy first.
    """

    __slots__ = ("array",)

    def __init__(self, array: NDArray[Any]):
        self.array = array


def _owned(array: NDArray[Any]) -> Any:
    """Wrap a fresh array for :class:`Motion` without a copy (see :class:`_Owned`)."""
    return _Owned(array)


def _take(value: Any, dtype: Any = float) -> tuple[NDArray[Any], bool]:
    """``(array, fresh)``: the value as an array, and whether nobody else holds it."""
    if isinstance(value, _Owned):
        arr = np.asarray(value.array, dtype=dtype)
        return arr, True
    arr = np.asarray(value, dtype=dtype)
    # a conversion from a list, or a dtype change, made a private copy already
    fresh = isinstance(value, (list, tuple)) or (
        isinstance(value, np.ndarray) and arr is not value and not np.may_share_memory(arr, value)
    )
    return arr, fresh


def _freeze(arr: NDArray[Any], fresh: bool) -> NDArray[Any]:
    del fresh  # readonly copies into immutable memory once, fresh or not
    return readonly(arr)


@dataclasses.dataclass(frozen=True, eq=False)
class Skeleton:
    """A joint hierarchy with rest offsets.

    Parameters
    ----------
    names : sequence of str, length J
        Unique joint names.
    parents : array_like of int, shape (J,)
        ``parents[0] == -1`` and ``0 <= parents[j] < j`` for ``j > 0``.
    offsets : array_like, shape (J, 3)
        Translation of each joint from its parent, in the parent's frame
        (metres).  The root's offset is kept for file round trips only.
    channels : sequence of sequence of str, optional
        BVH channel names per joint, in file order (defaults: 6 channels on
        the root, ``Zrotation Yrotation Xrotation`` elsewhere).
    end_site_parents : array_like of int, shape (E,), optional
        Joint that carries each BVH ``End Site``.
    end_site_offsets : array_like, shape (E, 3), optional
        Offset of each end site from its joint (metres).
    role_overrides : tuple of (role, joint name) pairs, optional
        Joint roles fixed by hand (see :meth:`with_roles`); the others are
        inferred (:attr:`roles`).

    Examples
    --------
    >>> sk = Skeleton(["hips", "knee"], [-1, 0], [[0, 0, 0], [0, -0.5, 0]])
    >>> sk.index("knee"), sk.n_joints
    (1, 2)
    """

    names: tuple[str, ...]
    parents: NDArray[np.int64]
    offsets: NDArray[np.float64]
    channels: tuple[tuple[str, ...], ...] = ()
    end_site_parents: NDArray[np.int64] = dataclasses.field(
        default_factory=lambda: np.zeros(0, dtype=np.int64)
    )
    end_site_offsets: NDArray[np.float64] = dataclasses.field(
        default_factory=lambda: np.zeros((0, 3))
    )
    role_overrides: tuple[tuple[str, Any], ...] = ()

    def __post_init__(self) -> None:
        names = tuple(str(n) for n in self.names)
        n = len(names)
        if n == 0:
            raise ValueError("Expected at least one joint in `names`, got none")
        if len(set(names)) != n:
            dup = sorted({x for x in names if names.count(x) > 1})
            raise ValueError(f"Expected unique joint names, got duplicates {dup}")
        parents = np.asarray(self.parents)
        if parents.shape != (n,) or not np.issubdtype(parents.dtype, np.integer):
            raise ValueError(f"Expected `parents` of {n} integers, got shape {parents.shape} dtype {parents.dtype}")
        if parents[0] != -1:
            raise ValueError(f"Expected parents[0] == -1 (the root), got {parents[0]}")
        bad = [j for j in range(1, n) if not 0 <= parents[j] < j]
        if bad:
            raise ValueError(f"Expected 0 <= parents[j] < j, violated at joints {bad[:5]}")
        offsets = np.asarray(self.offsets, dtype=float)
        if offsets.shape != (n, 3) or not np.all(np.isfinite(offsets)):
            raise ValueError(f"Expected finite `offsets` of shape ({n}, 3), got shape {offsets.shape}")
        channels = tuple(tuple(c) for c in self.channels)
        if not channels:
            channels = (DEFAULT_ROOT_CHANNELS,) + (DEFAULT_JOINT_CHANNELS,) * (n - 1)
        if len(channels) != n:
            raise ValueError(f"Expected channels for {n} joints, got {len(channels)}")
        for j, ch in enumerate(channels):
            unknown = [c for c in ch if c not in VALID_CHANNELS]
            if unknown or len(set(ch)) != len(ch):
                raise ValueError(f"Invalid channels {ch} for joint {names[j]!r}")
        esp = np.asarray(self.end_site_parents, dtype=np.int64).reshape(-1)
        eso = np.asarray(self.end_site_offsets, dtype=float).reshape(-1, 3)
        if esp.shape[0] != eso.shape[0] or np.any((esp < 0) | (esp >= n)):
            raise ValueError("Expected end_site_parents (E,) of joint indices matching end_site_offsets (E, 3)")
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "parents", _frozen(parents, np.int64))
        object.__setattr__(self, "offsets", _frozen(offsets))
        object.__setattr__(self, "channels", channels)
        object.__setattr__(self, "end_site_parents", _frozen(esp, np.int64))
        object.__setattr__(self, "end_site_offsets", _frozen(eso))
        overrides = dict(self.role_overrides.items() if isinstance(self.role_overrides, dict) else self.role_overrides)
        if overrides:
            Roles(names, overrides)  # role and joint names are checked here
        object.__setattr__(self, "role_overrides", tuple((k, overrides[k]) for k in sorted(overrides)))

    # ------------------------------------------------------------- roles
    @cached_property
    def roles(self) -> Roles:
        """The joint roles (pelvis, knees, wrists, ...), inferred once (see :mod:`mocaplab.roles`).

        Raises :class:`~mocaplab.roles.RolesError` only when a missing role
        is indexed; roles a skeleton lacks are simply absent.
        """
        return infer_roles(self, overrides=dict(self.role_overrides))

    def with_roles(self, **roles: Any) -> Skeleton:
        """A new skeleton with some joint roles named by hand.

        >>> sk = Skeleton(["root", "a", "b", "c"], [-1, 0, 1, 2], [[0, 0, 0], [0, -0.4, 0], [0, -0.4, 0], [0, 0, 0.1]])
        >>> sk.with_roles(left_ankle="b").roles["left_knee"]
        'a'
        """
        merged = dict(self.role_overrides)
        merged.update({k: v for k, v in roles.items()})
        merged = {k: v for k, v in merged.items() if v is not None}
        return dataclasses.replace(self, role_overrides=tuple(merged.items()))

    @property
    def n_joints(self) -> int:
        return len(self.names)

    def index(self, joint: str | int, *, arg: str = "joint") -> int:
        """Index of a joint given by name or by index (numpy integers too).

        The one place a joint reference is resolved: every function taking
        ``joint : str or int`` asks this method.

        Parameters
        ----------
        joint : str or int
            A joint name, or an index in ``[0, n_joints)``.
        arg : str
            The caller's argument name, used in the error message.

        Returns
        -------
        int

        Raises
        ------
        KeyError
            No joint has that name (the message lists the names).
        ValueError
            Neither a name nor an index in range.

        Examples
        --------
        >>> sk = Skeleton(["hips", "knee"], [-1, 0], [[0, 0, 0], [0, -0.4, 0]])
        >>> sk.index("knee"), sk.index(1)
        (1, 1)
        """
        if isinstance(joint, str):
            try:
                return self.names.index(joint)
            except ValueError:
                raise KeyError(f"No joint named {joint!r}; joints are {list(self.names)}") from None
        if isinstance(joint, (int, np.integer)) and not isinstance(joint, bool) and 0 <= int(joint) < self.n_joints:
            return int(joint)
        raise ValueError(f"Expected `{arg}` to be a joint name or an index in [0, {self.n_joints}), got {joint!r}")

    def children(self, j: int) -> list[int]:
        """Indices of the direct children of joint ``j``."""
        return [int(c) for c in np.flatnonzero(self.parents == j)]

    def depth(self) -> NDArray[np.int64]:
        """Number of edges from the root to each joint, shape (J,)."""
        return kinematics.joint_depths(self.parents)

    def chain(self, start: str | int, end: str | int) -> list[int]:
        """Joints from ``start`` down to its descendant ``end`` (both included)."""
        s, e = self.index(start, arg="start"), self.index(end, arg="end")
        out = [e]
        while out[-1] != s:
            if out[-1] <= 0:
                raise ValueError(f"{self.names[e]!r} does not descend from {self.names[s]!r}")
            out.append(int(self.parents[out[-1]]))
        return out[::-1]

    def scaled(self, factor: float) -> Skeleton:
        """The same skeleton with every length multiplied by ``factor``."""
        return dataclasses.replace(
            self, offsets=self.offsets * factor, end_site_offsets=self.end_site_offsets * factor
        )

    def mirror_map(self) -> NDArray[np.int64]:
        """For each joint, the index of its left/right counterpart (itself if none).

        Pairs come from the joint roles, the limb subtrees matched by shape,
        and the names (:func:`mocaplab.roles.mirror_map`).
        """
        return mirror_map(self)

    def describe(self) -> str:
        """An indented text tree of the hierarchy."""
        depth = self.depth()
        return "\n".join("  " * int(depth[j]) + self.names[j] for j in range(self.n_joints))


@dataclasses.dataclass(frozen=True, eq=False)
class Motion:
    """A clip: a skeleton animated by root positions and local rotations.

    Parameters
    ----------
    skeleton : Skeleton
    rotations : array_like, shape (F, J, 4)
        Local joint rotations as unit quaternions ``(x, y, z, w)``.
    root_positions : array_like, shape (F, 3)
        World position of the root joint, metres.
    fps : float
        Frames per second (> 0).
    translations : array_like, shape (F, J, 3), optional
        Animated local translations for files that put position channels on
        joints other than the root.  ``None`` means the skeleton offsets.
    name : str
        A label (file stem or clip id).

    Examples
    --------
    >>> import numpy as np
    >>> sk = Skeleton(["hips", "knee"], [-1, 0], [[0, 0, 0], [0, -0.5, 0]])
    >>> m = Motion(sk, np.tile([0, 0, 0, 1.0], (3, 2, 1)), np.zeros((3, 3)), 30.0)
    >>> m.n_frames, m.global_positions()[0, 1].tolist()
    (3, [0.0, -0.5, 0.0])
    """

    skeleton: Skeleton
    rotations: NDArray[np.float64]
    root_positions: NDArray[np.float64]
    fps: float
    translations: NDArray[np.float64] | None = None
    name: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.skeleton, Skeleton):
            raise TypeError(f"Expected `skeleton` to be a Skeleton, got {type(self.skeleton).__name__}")
        n = self.skeleton.n_joints
        rot, rot_fresh = _take(self.rotations)
        if rot.ndim != 3 or rot.shape[1:] != (n, 4) or rot.shape[0] < 1:
            raise ValueError(f"Expected `rotations` of shape (F, {n}, 4) with F >= 1, got {rot.shape}")
        frames = rot.shape[0]
        root, root_fresh = _take(self.root_positions)
        if root.shape != (frames, 3):
            raise ValueError(f"Expected `root_positions` of shape ({frames}, 3), got {root.shape}")
        # squared norms: finite exactly when every component is (or overflow,
        # which the unit check below reports)
        sq = np.einsum("fji,fji->fj", rot, rot)
        lo, hi = float(sq.min()), float(sq.max())
        finite_rot = np.isfinite(lo) and np.isfinite(hi) or bool(np.isfinite(rot).all())
        if not (finite_rot and np.isfinite(root).all()):
            raise ValueError("Expected finite `rotations` and `root_positions`, got NaN or inf")
        if lo < (1.0 - 1e-3) ** 2 or hi > (1.0 + 1e-3) ** 2:
            norms = np.sqrt(sq)
            worst = np.unravel_index(np.argmax(np.abs(norms - 1.0)), norms.shape)
            raise ValueError(
                f"Expected unit quaternions in `rotations`, got norm {norms[worst]:.6g} "
                f"at frame {worst[0]}, joint {self.skeleton.names[worst[1]]!r}"
            )
        if lo < 1.0 - 2e-14 or hi > 1.0 + 2e-14:
            rot = rot / np.sqrt(sq)[..., None]
            rot_fresh = True
        fps = _check_fps(self.fps)
        tr = self.translations
        if tr is not None:
            tr, tr_fresh = _take(tr)
            if tr.shape != (frames, n, 3) or not np.isfinite(tr).all():
                raise ValueError(f"Expected finite `translations` of shape ({frames}, {n}, 3), got {tr.shape}")
            tr = _freeze(tr, tr_fresh)
        object.__setattr__(self, "rotations", _freeze(rot, rot_fresh))
        object.__setattr__(self, "root_positions", _freeze(root, root_fresh))
        object.__setattr__(self, "fps", fps)
        object.__setattr__(self, "translations", tr)
        object.__setattr__(self, "name", str(self.name))

    # ------------------------------------------------------------------ sizes
    @property
    def n_frames(self) -> int:
        return int(self.rotations.shape[0])

    @property
    def n_joints(self) -> int:
        return self.skeleton.n_joints

    @property
    def dt(self) -> float:
        """Seconds between frames."""
        return 1.0 / self.fps

    @property
    def duration(self) -> float:
        """Seconds from the first to the last frame."""
        return (self.n_frames - 1) / self.fps

    @property
    def times(self) -> NDArray[np.float64]:
        """Time of each frame in seconds, shape (F,)."""
        return np.arange(self.n_frames) / self.fps

    def __len__(self) -> int:
        return self.n_frames

    def __repr__(self) -> str:
        label = f" {self.name!r}" if self.name else ""
        return f"<Motion{label}: {self.n_frames} frames, {self.n_joints} joints, {self.fps:g} fps>"

    # ------------------------------------------------------------ kinematics
    @cached_property
    def _fk(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        grot, gpos = kinematics.fk(
            self.rotations,
            self.root_positions,
            self.skeleton.offsets,
            self.skeleton.parents,
            translations=self.translations,
        )
        return readonly(grot), readonly(gpos)

    def global_positions(self) -> NDArray[np.float64]:
        """World joint positions, shape (F, J, 3), metres (read-only, cached)."""
        return self._fk[1]

    def global_rotations(self) -> NDArray[np.float64]:
        """World joint rotations, shape (F, J, 4) (read-only, cached)."""
        return self._fk[0]

    def end_site_positions(self) -> NDArray[np.float64]:
        """World positions of the end sites, shape (F, E, 3)."""
        sk = self.skeleton
        grot, gpos = self._fk
        return gpos[:, sk.end_site_parents] + quat.rotate(grot[:, sk.end_site_parents], sk.end_site_offsets)

    # ------------------------------------------------------------ the path
    @cached_property
    def path_joint(self) -> int:
        """Index of the joint that carries the character over the ground.

        The pelvis role (:attr:`Skeleton.roles`); for skeletons whose roles
        cannot be inferred, joint 0, unless joint 0 never moves and a joint
        below it carries animated translations (then the shallowest such
        joint).  A :class:`UserWarning` names the joint when it is not
        joint 0 (once per skeleton) (a static reference joint above a travelling pelvis is a
        common export layout).  Motion paths, editing, physical touch-up,
        staggered poses and the viewer follow this joint.
        """
        sk = self.skeleton
        try:
            j = sk.roles.index("pelvis")
        except RolesError:
            j = 0
            if self.translations is not None and np.ptp(self.root_positions, axis=0).max() < 1e-9:
                moving = np.flatnonzero(np.ptp(self.translations, axis=0).max(axis=-1) > 1e-6)
                if moving.size:
                    depth = sk.depth()
                    j = int(moving[np.argmin(depth[moving])])
        if j != 0 and not sk.__dict__.get("_path_joint_announced"):
            # once per skeleton: every edit of a clip shares it
            sk.__dict__["_path_joint_announced"] = True
            still = np.ptp(self.root_positions, axis=0).max() < 1e-9
            why = f"joint 0 {sk.names[0]!r} never moves" if still else "it is the pelvis"
            warn(
                f"The motion path follows joint {sk.names[j]!r} (index {j}), not joint 0: {why}",
                UserWarning,
            )
        return int(j)

    @property
    def pelvis_positions(self) -> NDArray[np.float64]:
        """World positions of :attr:`path_joint`, shape (F, 3) (the root's when it is joint 0)."""
        j = self.path_joint
        return self.root_positions if j == 0 else self.global_positions()[:, j]

    @property
    def pelvis_rotations(self) -> NDArray[np.float64]:
        """World rotations of :attr:`path_joint`, shape (F, 4)."""
        j = self.path_joint
        return self.rotations[:, 0] if j == 0 else self.global_rotations()[:, j]

    def joint_velocities(self) -> NDArray[np.float64]:
        """World joint velocities, shape (F, J, 3), metres per second."""
        return kinematics.velocities(self.global_positions(), self.fps)

    def joint_speeds(self) -> NDArray[np.float64]:
        """Norm of the joint velocities, shape (F, J), metres per second."""
        return np.linalg.norm(self.joint_velocities(), axis=-1)

    # ------------------------------------------------------------- editing
    def replace(self, **changes: Any) -> Motion:
        """A new Motion with some fields replaced (validated again).

        Arrays that are not replaced are shared with this motion (they are
        read-only), not copied.
        """
        for key in ("rotations", "root_positions", "translations"):
            if key not in changes and getattr(self, key) is not None:
                changes[key] = _Owned(getattr(self, key))
        return dataclasses.replace(self, **changes)

    def __getitem__(self, frames: slice) -> Motion:
        """Frame slicing: ``motion[10:100]`` or ``motion[::2]`` (fps adjusted)."""
        if not isinstance(frames, slice):
            raise TypeError(f"Expected a slice of frames, got {type(frames).__name__}")
        step = frames.step or 1
        if step <= 0:
            raise ValueError(f"Expected a positive slice step, got {step}")
        idx = np.arange(self.n_frames)[frames]
        if idx.size == 0:
            raise ValueError(f"Slice {frames} selects no frames of a {self.n_frames}-frame motion")
        return self.replace(
            rotations=_Owned(self.rotations[idx]),
            root_positions=_Owned(self.root_positions[idx]),
            translations=None if self.translations is None else _Owned(self.translations[idx]),
            fps=self.fps / step,
        )

    def resample(self, fps: float) -> Motion:
        """The same motion sampled at another frame rate (slerp / linear).

        The new clip covers the same time span (its last frame is at or before
        the old last frame's time).
        """
        fps = _check_fps(fps)
        n_new = int(np.floor(self.duration * fps + 1e-9)) + 1
        return self.sample(np.arange(n_new) / fps, fps=fps)

    def sample(self, times: ArrayLike, *, fps: float | None = None) -> Motion:
        """Poses at arbitrary times (seconds, clamped to the clip), as a Motion.

        Rotations are slerped and positions linearly interpolated between the
        two nearest frames.  ``fps`` labels the result (default: this clip's).
        """
        t = np.clip(np.asarray(times, dtype=float).reshape(-1), 0.0, self.duration)
        u = t * self.fps
        i0 = np.clip(np.floor(u).astype(np.int64), 0, self.n_frames - 1)
        i1 = np.minimum(i0 + 1, self.n_frames - 1)
        a = u - i0
        rot = quat.slerp(self.rotations[i0], self.rotations[i1], np.broadcast_to(a[:, None], (t.size, self.n_joints)))
        root = (1 - a)[:, None] * self.root_positions[i0] + a[:, None] * self.root_positions[i1]
        tr = None
        if self.translations is not None:
            tr = (1 - a)[:, None, None] * self.translations[i0] + a[:, None, None] * self.translations[i1]
        return self.replace(rotations=rot, root_positions=root, translations=tr, fps=self.fps if fps is None else fps)

    def mirror(self) -> Motion:
        """Mirror image across the ``x = 0`` plane, left and right joints swapped."""
        swap = self.skeleton.mirror_map()
        flip = np.array([-1.0, 1.0, 1.0])
        qflip = np.array([1.0, -1.0, -1.0, 1.0])
        sk = self.skeleton
        esp = swap[sk.end_site_parents]
        # keep end sites attached to the mirrored joint with that joint's mirrored offset
        eso = np.empty_like(sk.end_site_offsets)
        for e, (p, off) in enumerate(zip(sk.end_site_parents, sk.end_site_offsets, strict=True)):
            partner = np.flatnonzero(sk.end_site_parents == swap[p])
            eso[e] = (sk.end_site_offsets[partner[0]] if partner.size else off) * flip
        new_sk = dataclasses.replace(
            sk, offsets=sk.offsets[swap] * flip, end_site_parents=sk.end_site_parents, end_site_offsets=eso
        )
        del esp
        tr = None if self.translations is None else self.translations[:, swap] * flip
        return self.replace(
            skeleton=new_sk,
            rotations=self.rotations[:, swap] * qflip,
            root_positions=self.root_positions * flip,
            translations=tr,
        )

    def with_root(
        self, *, root_positions: ArrayLike | None = None, root_rotations: ArrayLike | None = None
    ) -> Motion:
        """A new Motion with the root trajectory and/or root orientation replaced."""
        rot = self.rotations
        if root_rotations is not None:
            new_root = np.asarray(root_rotations, dtype=float)
            if new_root.shape != (self.n_frames, 4):
                raise ValueError(
                    f"Expected `root_rotations` of shape ({self.n_frames}, 4), got {new_root.shape}"
                )
            rot = np.array(self.rotations, copy=True)
            rot[:, 0] = new_root
        root = self.root_positions if root_positions is None else root_positions
        return self.replace(rotations=rot, root_positions=root)

    def transformed(
        self,
        *,
        yaw: ArrayLike = 0.0,
        translation: ArrayLike = (0.0, 0.0, 0.0),
        rotation: ArrayLike | None = None,
    ) -> Motion:
        """Rigidly turn the clip by ``yaw`` radians about the vertical axis
        through the origin, then translate it.

        ``yaw`` may be one angle or one per frame, shape (F,); ``translation``
        shape (3,) or (F, 3): a per-frame rigid motion of the whole body
        (``x -> R x + t``), applied at joint 0 so that every joint moves with
        it; when joint 0 is a static reference above a travelling pelvis (the
        path joint, with animated translations: :attr:`carrier_joint`), it is
        applied at the pelvis instead and the reference stays where it is.
        ``rotation``, a unit quaternion of shape (4,) or (F, 4), turns about
        the origin instead of ``yaw`` (give one of them).
        """
        yaw = np.asarray(yaw, dtype=float)
        if yaw.shape not in ((), (self.n_frames,)):
            raise ValueError(f"Expected `yaw` as one angle or shape ({self.n_frames},), got {yaw.shape}")
        t = np.asarray(translation, dtype=float)
        if t.shape not in ((3,), (self.n_frames, 3)):
            raise ValueError(f"Expected `translation` of shape (3,) or ({self.n_frames}, 3), got {t.shape}")
        if rotation is None:
            q = quat.from_yaw(yaw)
        else:
            if np.any(yaw != 0):
                raise ValueError("Expected `yaw` or `rotation`, got both")
            q = np.asarray(rotation, dtype=float)
            if q.shape not in ((4,), (self.n_frames, 4)) or not np.all(np.isfinite(q)):
                raise ValueError(f"Expected a finite `rotation` of shape (4,) or ({self.n_frames}, 4), got {q.shape}")
            q = quat.normalize(q)
        top = self.carrier_joint
        if top != 0:
            return self._transformed_at(top, q, t)
        root = quat.rotate(q, self.root_positions) + t
        return self.with_root(root_positions=root, root_rotations=quat.mul(q, self.rotations[:, 0]))

    @property
    def carrier_joint(self) -> int:
        """The joint that carries the whole body over the ground: 0, or the pelvis below a static root.

        The path joint when every joint above it is static and it carries
        animated translations, else joint 0.  :meth:`transformed` (so every
        edit that moves a clip over the ground) and displacement maps
        translate the body at this joint.

        A static reference root above a travelling pelvis (a common export
        layout) stays static when the clip is moved over the ground: the
        rigid motion goes onto the pelvis, so a moved clip has the same
        animated channels as the original, like the same clip with the pelvis
        at joint 0 (staggered poses and other per-channel methods then see
        the same variables).
        """
        if self.translations is None:
            return 0
        j = self.path_joint
        if j == 0:
            return 0
        above = [0]
        a = int(self.skeleton.parents[j])
        while a > 0:
            above.append(a)
            a = int(self.skeleton.parents[a])
        tol = 1e-9
        if np.ptp(self.root_positions, axis=0).max() > tol:
            return 0
        if np.ptp(self.rotations[:, above], axis=0).max() > tol or np.ptp(self.translations[:, above[1:]], axis=0).max(
            initial=0.0
        ) > tol:
            return 0
        return j

    def _transformed_at(self, j: int, q: NDArray[np.float64], t: NDArray[np.float64]) -> Motion:
        """:meth:`transformed` applied at joint ``j`` below a static chain (world ``G * W_parent * L_j``)."""
        from .kinematics import fk

        sk = self.skeleton
        tr = self.translations
        assert tr is not None  # carrier_joint is 0 without translations
        p = int(sk.parents[j])
        grot, gpos = fk(self.rotations[:1], self.root_positions[:1], sk.offsets, sk.parents, translations=tr[:1])
        ra, oa = grot[0, p], gpos[0, p]
        ra_inv = quat.inv(ra)
        world = oa + quat.rotate(ra, tr[:, j])
        moved = quat.rotate(q, world) + t
        rotations = np.array(self.rotations)
        translations = np.array(tr)
        rotations[:, j] = quat.normalize(quat.mul(ra_inv, quat.mul(q, quat.mul(ra, self.rotations[:, j]))))
        translations[:, j] = quat.rotate(ra_inv, moved - oa)
        return self.replace(rotations=rotations, translations=translations)


def concatenate(motions: Sequence[Motion]) -> Motion:
    """Join clips end to end (same skeleton and fps); no alignment or blending.

    Parameters
    ----------
    motions : sequence of Motion
        At least one; all with the joint names, offsets and frame rate of the
        first.  Per-frame translations, where only some clips have them, are
        filled with the skeleton's offsets for the others.

    Returns
    -------
    Motion
        The first motion's skeleton, name and fps, with ``sum(n_frames)``
        frames.

    Raises
    ------
    ValueError
        For no motion, another skeleton or another frame rate (naming the clip).

    Examples
    --------
    >>> import numpy as np
    >>> sk = Skeleton(["hips", "knee"], [-1, 0], [[0, 0, 0], [0, -0.5, 0]])
    >>> a = Motion(sk, np.tile([0, 0, 0, 1.0], (3, 2, 1)), np.zeros((3, 3)), 30)
    >>> joined = concatenate([a, a.replace(root_positions=np.ones((3, 3)))])
    >>> joined.n_frames, joined.root_positions[:, 0].tolist()
    (6, [0.0, 0.0, 0.0, 1.0, 1.0, 1.0])
    """
    if not motions:
        raise ValueError("Expected at least one motion to concatenate, got none")
    first = motions[0]
    for k, m in enumerate(motions[1:], start=1):
        if m.skeleton.names != first.skeleton.names or not np.allclose(m.skeleton.offsets, first.skeleton.offsets):
            raise ValueError(f"Motion {k} has a different skeleton from motion 0")
        if abs(m.fps - first.fps) > 1e-5 * first.fps:  # BVH frame times often carry 5 significant digits
            raise ValueError(f"Motion {k} runs at {m.fps} fps, motion 0 at {first.fps} fps")
    has_tr = [m.translations is not None for m in motions]
    tr = None
    if any(has_tr):
        tr = np.concatenate(
            [
                m.translations if m.translations is not None else np.broadcast_to(m.skeleton.offsets, (m.n_frames, m.n_joints, 3))
                for m in motions
            ]
        )
    return first.replace(
        rotations=np.concatenate([m.rotations for m in motions]),
        root_positions=np.concatenate([m.root_positions for m in motions]),
        translations=tr,
    )
