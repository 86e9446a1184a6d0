"""Which joints touch the environment, and when.

Two detectors return the same :class:`Contacts` object, a per-joint boolean
mask over frames:

* :func:`foot_contacts`, after Kim et al. 2009 §4.3: a joint is in contact
  with the ground on the frames where it is *close to the ground* **and**
  *slow*.  Thresholds are in metres and metres per second.
* :func:`stillness_contacts`, after Coleman et al. 2008 Appendix B: scanning
  forward in time, a joint whose world position stays within a tolerance for
  at least a minimum time (0.25 s, or scaled to the gait for runs) starts a
  contact, which is then expanded over the neighbouring frames that stay
  within the tolerance.

Frame intervals are half-open ``(start, stop)`` pairs: frames
``start, ..., stop - 1``.  :func:`intervals_from_mask` and
:func:`mask_from_intervals` convert between the two forms.

Examples
--------
>>> import numpy as np
>>> intervals_from_mask(np.array([0, 1, 1, 0, 1], dtype=bool))
[(1, 3), (4, 5)]
>>> mask_from_intervals([(1, 3)], 4).tolist()
[False, True, True, False]

Longer than 800 lines because contact detection, the Contacts record, the one reader of ``contacts=`` and the floor estimate share the planted-sample logic, and each entry point carries a runnable example.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline

from .anatomy import foot_balls
from .motion import Motion, readonly
from .roles import RolesError, resolve_roles

__all__ = [
    "Contacts",
    "foot_contacts",
    "resolve_contacts",
    "stillness_contacts",
    "default_foot_joints",
    "intervals_from_mask",
    "mask_from_intervals",
    "clean_mask",
    "Floor",
    "estimate_floor",
]

# --------------------------------------------------------------------------
# the result type
# --------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True, eq=False)
class Contacts:
    """Per-joint contact flags over the frames of a clip.

    Parameters
    ----------
    joints : sequence of str, length n
        Joint names, one per column of ``mask``.
    mask : array_like of bool, shape (F, n)
        ``mask[i, k]`` is True when joint ``joints[k]`` is in contact on frame ``i``.
    fps : float
        Frames per second of the clip the mask was computed on.

    Examples
    --------
    >>> import numpy as np
    >>> c = Contacts(("LeftFoot",), np.array([[0], [1], [1], [0]], dtype=bool), 120.0)
    >>> c.intervals("LeftFoot"), c.n_frames
    ([(1, 3)], 4)
    """

    joints: tuple[str, ...]
    mask: NDArray[np.bool_]
    fps: float

    def __post_init__(self) -> None:
        joints = tuple(str(j) for j in self.joints)
        if len(set(joints)) != len(joints):
            raise ValueError(f"Expected unique names in `joints`, got {list(joints)}")
        mask = np.asarray(self.mask)
        if mask.ndim == 1 and len(joints) == 1:
            mask = mask[:, None]
        if mask.ndim != 2 or mask.shape[1] != len(joints):
            raise ValueError(f"Expected `mask` of shape (F, {len(joints)}), got {mask.shape}")
        if mask.dtype != np.bool_:
            if not np.all((mask == 0) | (mask == 1)):
                raise ValueError(f"Expected a boolean `mask`, got dtype {mask.dtype} with values other than 0/1")
        mask = readonly(np.array(mask, dtype=bool, copy=True))
        fps = float(self.fps)
        if not np.isfinite(fps) or fps <= 0:
            raise ValueError(f"Expected `fps` > 0, got {self.fps!r}")
        object.__setattr__(self, "joints", joints)
        object.__setattr__(self, "mask", mask)
        object.__setattr__(self, "fps", fps)

    @property
    def n_frames(self) -> int:
        """Number of frames F."""
        return int(self.mask.shape[0])

    @property
    def times(self) -> NDArray[np.float64]:
        """Time of each frame in seconds, shape (F,)."""
        return np.arange(self.n_frames) / self.fps

    def index(self, joint: str) -> int:
        """Column of ``joint`` in :attr:`mask` (KeyError listing the joints if absent)."""
        try:
            return self.joints.index(joint)
        except ValueError:
            raise KeyError(f"No contacts for joint {joint!r}; joints are {list(self.joints)}") from None

    def of(self, joint: str) -> NDArray[np.bool_]:
        """Contact flags of one joint, shape (F,) (read-only)."""
        return self.mask[:, self.index(joint)]

    def slide(self, motion: Motion) -> NDArray[np.float64]:
        """Horizontal slide of the planted joints of ``motion``, mm per frame, shape (F - 1,).

        Entry ``i`` is the largest ground-plane distance ``|p(i+1) - p(i)|``
        over the joints planted on both frames ``i`` and ``i + 1``; NaN where
        none is (:func:`mocaplab.quality.skate`, the measure, reads it).
        """
        if self.n_frames != motion.n_frames:
            raise ValueError(f"Expected contacts over {motion.n_frames} frames, got {self.n_frames}")
        idx = [motion.skeleton.index(j) for j in self.joints]
        pos = motion.global_positions()[:, idx][:, :, [0, 2]]
        slide = np.linalg.norm(np.diff(pos, axis=0), axis=-1) * 1000.0
        both = self.mask[1:] & self.mask[:-1]
        out = np.where(both, slide, -np.inf).max(axis=1, initial=-np.inf)
        return np.where(both.any(axis=1), out, np.nan)

    def intervals(self, joint: str) -> list[tuple[int, int]]:
        """Half-open frame intervals ``[(start, stop), ...]`` where ``joint`` is in contact."""
        return intervals_from_mask(self.of(joint))

    def planted_any(self) -> NDArray[np.bool_]:
        """True on frames where at least one joint is in contact, shape (F,)."""
        return np.asarray(self.mask.any(axis=1), dtype=bool)

    def fraction(self, joint: str) -> float:
        """Share of the frames on which ``joint`` is in contact, in [0, 1]."""
        return float(self.of(joint).mean())

    def __repr__(self) -> str:
        parts = ", ".join(f"{j}: {self.fraction(j):.0%}" for j in self.joints)
        return f"<Contacts {self.n_frames} frames at {self.fps:g} fps; {parts}>"


# --------------------------------------------------------------------------
# masks and intervals
# --------------------------------------------------------------------------
def intervals_from_mask(mask: ArrayLike) -> list[tuple[int, int]]:
    """Runs of True in a boolean vector, as half-open ``(start, stop)`` intervals.

    Parameters
    ----------
    mask : array_like of bool, shape (F,)

    Returns
    -------
    list of (int, int)
        Sorted, disjoint, non-adjacent intervals.

    Raises
    ------
    ValueError
        If ``mask`` is not one-dimensional.

    Examples
    --------
    >>> intervals_from_mask([0, 1, 1, 0, 1, 1, 1])
    [(1, 3), (4, 7)]
    """
    m = np.asarray(mask, dtype=bool)
    if m.ndim != 1:
        raise ValueError(f"Expected a 1-D `mask` of shape (F,), got shape {m.shape}")
    edges = np.diff(np.concatenate(([0], m.astype(np.int8), [0])))
    starts = np.flatnonzero(edges == 1)
    stops = np.flatnonzero(edges == -1)
    return [(int(a), int(b)) for a, b in zip(starts, stops, strict=True)]


def mask_from_intervals(intervals: Iterable[tuple[int, int]], n: int) -> NDArray[np.bool_]:
    """Boolean vector of length ``n``, True inside the half-open intervals.

    Parameters
    ----------
    intervals : iterable of (int, int)
        ``(start, stop)`` pairs with ``0 <= start <= stop <= n``.
    n : int
        Number of frames.

    Returns
    -------
    ndarray of bool, shape (n,)

    Raises
    ------
    ValueError
        If ``n`` is negative or an interval leaves ``[0, n]``.

    Examples
    --------
    >>> mask_from_intervals([(1, 3), (4, 5)], 6).astype(int).tolist()
    [0, 1, 1, 0, 1, 0]
    """
    n = int(n)
    if n < 0:
        raise ValueError(f"Expected `n` >= 0, got {n}")
    out = np.zeros(n, dtype=bool)
    for start, stop in intervals:
        a, b = int(start), int(stop)
        if not 0 <= a <= b <= n:
            raise ValueError(f"Expected intervals with 0 <= start <= stop <= {n}, got ({start}, {stop})")
        out[a:b] = True
    return out


def clean_mask(mask: ArrayLike, *, min_length: int = 1, max_gap: int = 0) -> NDArray[np.bool_]:
    """Fill short gaps between contacts, then drop contacts that are too short.

    Parameters
    ----------
    mask : array_like of bool, shape (F,) or (F, n)
        Columns are cleaned independently.
    min_length : int
        Runs of True shorter than this many frames become False.
    max_gap : int
        Runs of False of at most this many frames *between two runs of True*
        become True (a gap touching the clip's first or last frame is kept).

    Returns
    -------
    ndarray of bool, same shape as ``mask``

    Examples
    --------
    The one-frame gap is filled; the lone last frame is too short:

    >>> clean_mask([1, 1, 0, 1, 1, 0, 0, 0, 1], min_length=2, max_gap=1).astype(int).tolist()
    [1, 1, 1, 1, 1, 0, 0, 0, 0]
    """
    m = np.asarray(mask, dtype=bool)
    if m.ndim not in (1, 2):
        raise ValueError(f"Expected `mask` of shape (F,) or (F, n), got {m.shape}")
    cols = m[:, None] if m.ndim == 1 else m
    out = np.array(cols, copy=True)
    n = cols.shape[0]
    for k in range(cols.shape[1]):
        runs = intervals_from_mask(cols[:, k])
        if max_gap > 0 and len(runs) > 1:
            merged = [runs[0]]
            for a, b in runs[1:]:
                if a - merged[-1][1] <= max_gap:
                    merged[-1] = (merged[-1][0], b)
                else:
                    merged.append((a, b))
            runs = merged
        out[:, k] = mask_from_intervals([(a, b) for a, b in runs if b - a >= min_length], n)
    return out[:, 0] if m.ndim == 1 else out


# --------------------------------------------------------------------------
# joint selection
# --------------------------------------------------------------------------
def default_foot_joints(skeleton_or_motion: object, *, roles: Mapping[str, Any] | None = None) -> tuple[str, ...]:
    """The ankle and toe joints of both feet, from the skeleton's joint roles.

    CMU skeletons give ``("LeftFoot", "LeftToeBase", "RightFoot",
    "RightToeBase")``; the Daz skeleton of the CMU salsa clips, which has no
    toe joints, gives ``("lFoot", "rFoot")``.

    Parameters
    ----------
    skeleton_or_motion : Skeleton or Motion
    roles : mapping, optional
        Role overrides, as in :func:`mocaplab.roles.resolve_roles`.

    Returns
    -------
    tuple of str
        Joint names, left foot first.

    Raises
    ------
    RolesError
        (a ValueError) naming the missing roles and the call that supplies
        them, when a side has no ankle.

    Examples
    --------
    >>> import mocaplab as ml
    >>> default_foot_joints(ml.cmu("16_15"))
    ('LeftFoot', 'LeftToeBase', 'RightFoot', 'RightToeBase')
    """
    return resolve_roles(skeleton_or_motion, roles).foot_joints()


def _resolve(
    motion: Motion, joints: Sequence[str] | None, roles: Mapping[str, Any] | None = None
) -> tuple[tuple[str, ...], NDArray[np.int64]]:
    if not isinstance(motion, Motion):
        raise TypeError(f"Expected `motion` to be a Motion, got {type(motion).__name__}")
    if joints is None:
        names = default_foot_joints(motion, roles=roles)
    else:
        if isinstance(joints, str):
            joints = (joints,)
        names = tuple(str(j) for j in joints)
        if not names:
            raise ValueError("Expected at least one joint name in `joints`, got none")
    idx = np.array([motion.skeleton.index(n) for n in names], dtype=np.int64)
    return names, idx


def _frames(seconds: float, fps: float, what: str) -> int:
    if not np.isfinite(seconds) or seconds < 0:
        raise ValueError(f"Expected `{what}` >= 0 seconds, got {seconds!r}")
    return int(round(seconds * fps))


# --------------------------------------------------------------------------
# Kim et al. 2009 §4.3: close to the ground and slow
# --------------------------------------------------------------------------
def foot_contacts(
    motion: Motion,
    *,
    joints: Sequence[str] | None = None,
    roles: Mapping[str, Any] | None = None,
    height: float = 0.06,
    speed: float = 0.6,
    min_duration: float = 0.05,
    max_gap: float = 0.04,
    floor: Literal["clip", "ground"] = "clip",
    floor_percentile: float = 5.0,
) -> Contacts:
    """Foot-ground contacts: frames where a joint is low **and** slow.

    Kim et al. 2009 §4.3 identify a foot-ground contact "if the foot is
    sufficiently close to the ground and its velocity is below a threshold";
    the paper gives no numbers, so the choices here are documented below.

    Parameters
    ----------
    motion : Motion
    joints : sequence of str, optional
        Joints to test; default :func:`default_foot_joints` (ankle and toe of
        each foot, from the joint roles).  Each joint is tested on its own: a
        foot is planted when its ankle *or* its toe is.
    roles : mapping, optional
        Joint-role overrides (:func:`mocaplab.roles.resolve_roles`).
    height : float
        Height threshold, metres.  With ``floor="clip"`` (default) the height
        is measured **above the joint's own floor level in this clip**, the
        ``floor_percentile`` percentile of the joint's height over the clip:
        an ankle rests about 8 cm above the sole and CMU floors are often
        tilted by a few centimetres over a capture volume, so a per-joint,
        per-clip reference is more robust than y = 0.  It assumes the joint
        does touch the ground somewhere in the clip.  With ``floor="ground"``
        the height is the joint's absolute y (ground at y = 0).
    speed : float
        Speed threshold, metres per second (world speed of the joint, from
        a cubic spline through its positions: see Notes).  A swinging foot
        moves at 2-8 m/s, a planted one below about 0.3 m/s; 0.6 m/s also
        keeps the toe's roll at push-off.
    min_duration : float
        Contacts shorter than this many seconds are dropped (noise blips).
    max_gap : float
        Gaps of at most this many seconds inside a contact are filled (they
        are filled before short contacts are dropped).
    floor : {"clip", "ground"}
        Height reference, see ``height``.
    floor_percentile : float
        Percentile (0-100) of a joint's heights taken as its floor level.

    Returns
    -------
    Contacts
        Mask of shape (F, len(joints)).

    Notes
    -----
    **The same contacts in time at any frame rate.**  A frame is labelled
    with the state of the joint at the frame's own instant, and that state
    is decided on :data:`SUBFRAME_RATE` samples per second (every 2 ms at
    30 fps as at 120 fps) of a cubic spline through the joint's positions:
    the speed is the spline's, at that instant, where central differences
    averaged it over two frame intervals (67 ms at 30 fps, across a heel
    strike); contacts shorter than ``min_duration`` and gaps up to
    ``max_gap`` are judged in seconds on those samples, not in whole
    frames.  So a contact that starts between two frames starts on the
    later one at any rate: its onset is half a frame before its first
    planted frame, give or take half a frame (on CMU walks resampled to
    30 fps, heel strikes and toe-offs within 17 ms of those at 120 fps),
    and a clip is planted on the same share of its frames at 24 or 120 fps.
    (Labelling the frame *nearest* each onset instead would plant every
    contact half a frame longer at each end, 33 ms at 30 fps: a 30 fps
    walk would then balance 23 % better than the same walk at 120 fps.)

    The defaults were checked on the CMU clips at 120 fps: on the walks 16_15
    and 02_01 each foot is planted for about 55-65 % of the time, with double
    support in between; on the run 09_06 there are flight phases with no
    contact at all.

    Examples
    --------
    >>> from mocaplab.data import cmu
    >>> c = foot_contacts(cmu("16_15"))
    >>> c.intervals("LeftFoot")[:2]
    [(0, 68), (135, 208)]
    """
    names, idx = _resolve(motion, joints, roles)
    for value, what in ((height, "height"), (speed, "speed")):
        if not np.isfinite(value) or value <= 0:
            raise ValueError(f"Expected `{what}` > 0, got {value!r}")
    if floor not in ("clip", "ground"):
        raise ValueError(f"Expected `floor` to be 'clip' or 'ground', got {floor!r}")
    if not 0.0 <= floor_percentile <= 100.0:
        raise ValueError(f"Expected `floor_percentile` in [0, 100], got {floor_percentile!r}")
    fps = motion.fps
    pos = motion.global_positions()[:, idx]
    balls = _balls(motion, names, roles)
    if balls:
        # a foot without a toe joint is also planted while it rolls over its ball (toe-off)
        pos = np.concatenate([pos, np.stack([balls[n] for n in names if n in balls], axis=1)], axis=1)
    per_frame = _subframes(fps)
    fine, v = _subframe_tracks(pos, per_frame)  # (S, n, 3), (S, n) with S = (F - 1) * per_frame + 1
    v = v * fps
    y = fine[..., 1]
    if floor == "clip":
        at_frames = slice(None, None, per_frame)
        slope = _slope(pos, v[at_frames] < speed)
        y = y - fine[..., [0, 2]] @ slope
        y = y - np.percentile(y[at_frames], floor_percentile, axis=0)
    raw = (y < height) & (v < speed)
    if balls:
        n = len(names)
        cols = [k for k, name in enumerate(names) if name in balls]
        raw[:, cols] |= raw[:, n:]
        raw = raw[:, :n]
    rate = fps * per_frame
    raw = clean_mask(
        raw,
        min_length=max(1, _frames(min_duration, rate, "min_duration")),
        max_gap=_frames(max_gap, rate, "max_gap"),
    )
    return Contacts(names, raw[::per_frame], fps)


def resolve_contacts(
    contacts: Contacts | Literal["auto"] | None,
    motion: Motion,
    *,
    roles: Mapping[str, Any] | None = None,
    arg: str = "contacts",
) -> Contacts | None:
    """The one meaning of a ``contacts=`` argument anywhere in mocaplab.

    Parameters
    ----------
    contacts : "auto", None or Contacts
        ``"auto"``: :func:`foot_contacts` of ``motion`` (detected);
        ``None``: no contacts; a :class:`Contacts`: these, checked against
        ``motion``'s frame count.
    motion : Motion
        The motion contacts are detected on (for ``"auto"``): callers pass
        the motion before an edit when they have it, whose contacts are right.
    roles : mapping, optional
        Joint-role overrides for the detection.
    arg : str
        The caller's argument name, for the error message.

    Returns
    -------
    Contacts or None

    Examples
    --------
    >>> import numpy as np
    >>> from mocaplab.motion import Motion, Skeleton
    >>> m = Motion(Skeleton(["hips"], [-1], [[0.0, 0.0, 0.0]]), np.tile([0.0, 0, 0, 1], (5, 1, 1)), np.zeros((5, 3)), fps=30)
    >>> resolve_contacts(None, m) is None
    True
    >>> resolve_contacts(Contacts(["hips"], np.ones((5, 1), bool), 30.0), m).n_frames
    5
    """
    if isinstance(contacts, str) and contacts == "auto":
        return foot_contacts(motion, roles=roles)
    if contacts is None:
        return None
    if not isinstance(contacts, Contacts):
        raise TypeError(
            f'Expected `{arg}` to be "auto" (detect), None (no contacts) or a mocaplab.contacts.Contacts, '
            f"got {type(contacts).__name__} {contacts!r}"[:300]
        )
    if contacts.n_frames != motion.n_frames:
        raise ValueError(f"Expected `{arg}` over {motion.n_frames} frames, got {contacts.n_frames}")
    return contacts


#: Floors inclined by less than this (degrees) are level: :func:`estimate_floor`
#: returns them with a zero slope (so the methods, which follow
#: :attr:`Floor.slope`, and :mod:`mocaplab.quality`'s penetration, which
#: measures against it, see the same floor), and :func:`foot_contacts` tests
#: heights above a level plane.  A plane fitted to the contacts of one take
#: tilts by up to a degree, and one take cannot tell a stage's calibration
#: tilt from a drift of the planted heights along the walk: on the CMU walks
#: and runs of the mirror the fit rises 10-15 mm per metre along the travel in
#: three takes of two sessions (02_01 going +z, 127_04 and 127_21 going -z) and
#: falls 2-5 mm/m in subject 16's.  Extrapolated to where an edit moves the
#: feet, such a tilt moves the plants by the tilt times the distance (7 mm for
#: a squeeze of 1.6 m on 16_15).  The price: over a take whose planted heights
#: do drift, the penetration measure cannot see a foot sunk by less than the
#: drift at the high end (up to 40-50 mm on 127_04).
LEVEL_FLOOR_ANGLE = 2.0


def _levelled(slope: NDArray[np.float64]) -> NDArray[np.float64]:
    """``slope`` (2,), or zeros for a floor within :data:`LEVEL_FLOOR_ANGLE` of level."""
    return slope if np.degrees(np.arctan(np.linalg.norm(slope))) >= LEVEL_FLOOR_ANGLE else np.zeros(2)


#: Samples per second at which :func:`foot_contacts` tests heights and speeds
#: (at least one per frame): contacts are timed to about 2 ms at any frame rate.
SUBFRAME_RATE = 480.0


def _subframes(fps: float) -> int:
    """Samples per frame interval for :data:`SUBFRAME_RATE` (at least 1)."""
    return max(1, int(np.ceil(SUBFRAME_RATE / fps - 1e-9)))


def _subframe_tracks(pos: NDArray[np.float64], per_frame: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Points (F, n, 3) on ``per_frame`` samples per frame interval, and their speeds in units per frame.

    A cubic spline through the frames gives the positions (through every
    frame exactly) and the velocities between them; its natural ends (no
    curvature at the first and last frames) keep the speed there from
    being extrapolated from the next few frames.  Returns
    shapes (S, n, 3) and (S, n) with ``S = (F - 1) * per_frame + 1``; sample
    ``i * per_frame`` is frame ``i``.
    """
    n_frames = pos.shape[0]
    if n_frames < 2:
        return np.array(pos, dtype=float), np.zeros(pos.shape[:-1])
    spline = CubicSpline(np.arange(n_frames), pos, axis=0, bc_type="natural")
    t = np.arange((n_frames - 1) * per_frame + 1) / per_frame
    return spline(t), np.linalg.norm(spline(t, 1), axis=-1)


def _balls(motion: Motion, names: tuple[str, ...], roles: Mapping[str, Any] | None) -> dict[str, NDArray[np.float64]]:
    """Ball positions of the tested ankles whose feet have no toe joint (see :func:`mocaplab.anatomy.foot_balls`)."""
    try:
        feet = resolve_roles(motion, roles).feet()
    except RolesError:
        return {}
    if not any(toe is None and ankle in names for ankle, toe in feet):
        return {}
    try:
        balls = foot_balls(motion, roles=roles)
    except RolesError:
        return {}  # no geometry to estimate the toe from: the ankle alone
    return {name: p for name, p in balls.items() if name in names}


def _slope(pos: NDArray[np.float64], slow: NDArray[np.bool_]) -> NDArray[np.float64]:
    """Slope of the floor under slow points (F, n, 3), (0, 0) when within :data:`LEVEL_FLOOR_ANGLE` of level."""
    if not slow.any():
        return np.zeros(2)
    return _levelled(_fit_slope(pos, slow))


# --------------------------------------------------------------------------
# Coleman et al. 2008 Appendix B: still within a tolerance for 0.25 s
# --------------------------------------------------------------------------
GAIT_TRAVEL = 0.3
"""Metres the body travels over a planted foot in ``min_duration="gait"`` (0.25 s at a brisk 1.2 m/s walk)."""


def stillness_contacts(
    motion: Motion,
    *,
    joints: Sequence[str] | None = None,
    roles: Mapping[str, Any] | None = None,
    tolerance: float = 0.03,
    min_duration: float | Literal["gait"] = 0.25,
    max_height: float | None = None,
    travel: float = GAIT_TRAVEL,
) -> Contacts:
    """Environmental contacts: joints that stay still for long enough.

    Coleman et al. 2008 Appendix B: search forward in time for joints whose
    world positions remain within a tolerance for a minimum time (0.25 s);
    when found, create a constraint and expand it in time over the further
    frames that remain within the tolerance.

    Choices made here, where the paper leaves them open:

    * a window of ``min_duration`` seconds is *still* when every position in
      it lies within ``tolerance`` of the window's mean position, its
      **anchor** (the position the constraint would pin);
    * the first still window after the end of the previous contact starts a
      contact, which then grows forward, and backward down to the previous
      contact, over every consecutive frame within ``tolerance`` of the
      anchor; the search resumes after its last frame.

    Parameters
    ----------
    motion : Motion
    joints : sequence of str, optional
        Default :func:`default_foot_joints`.  Any joint works (hands on a
        rail, a knee on the floor).
    roles : mapping, optional
        Joint-role overrides (:func:`mocaplab.roles.resolve_roles`).
    tolerance : float
        Radius in metres.  The paper sets it "slightly larger than the
        apparent error introduced by noise"; 3 cm suits CMU feet at 120 fps
        (a planted ankle drifts 1-2 cm as the foot rolls).
    min_duration : float or "gait"
        Minimum still time in seconds (0.25 s in the paper).  ``"gait"``
        scales it to the gait: a window starting at a frame must last
        ``min(0.25 s, travel / v)``, ``v`` being the pelvis's mean horizontal
        speed over the next 0.25 s (at least 2 frames).  The paper's 0.25 s
        holds up to a brisk walk; in a run a planted foot is still for only
        0.07-0.13 s (CMU 09_06, 16_35) and 0.25 s finds no contact at all.
        Jumps in place keep 0.25 s, so a foot briefly still at the top of a
        vertical jump is not taken for a contact; and a joint moving with a
        fast body cannot be still in the world, whatever the window.
    max_height : float, optional
        If given, frames where the joint is higher than this (metres, absolute
        y) cannot be in contact: a way to ignore a foot held still in the air.
    travel : float
        Metres of pelvis travel for ``min_duration="gait"`` (default 0.3 m).

    Returns
    -------
    Contacts
        Mask of shape (F, len(joints)).

    Raises
    ------
    ValueError
        If ``tolerance`` is not a positive number of metres or
        ``min_duration`` is neither seconds nor ``"gait"``.

    Examples
    --------
    >>> from mocaplab.data import cmu
    >>> c = stillness_contacts(cmu("16_15"), joints=["LeftFoot"])
    >>> c.intervals("LeftFoot")[:2]
    [(0, 57), (138, 198)]
    """
    names, idx = _resolve(motion, joints, roles)
    if not np.isfinite(tolerance) or tolerance <= 0:
        raise ValueError(f"Expected `tolerance` > 0 metres, got {tolerance!r}")
    n_frames = motion.n_frames
    if isinstance(min_duration, str):
        if min_duration != "gait":
            raise ValueError(f"Expected `min_duration` in seconds or 'gait', got {min_duration!r}")
        if not np.isfinite(travel) or travel <= 0:
            raise ValueError(f"Expected `travel` > 0 metres, got {travel!r}")
        lengths = _gait_windows(motion, travel)
    else:
        lengths = np.full(n_frames, max(2, _frames(min_duration, motion.fps, "min_duration")))
    pos = motion.global_positions()[:, idx]  # (F, n, 3)
    mask = np.zeros((n_frames, len(names)), dtype=bool)
    allowed = np.ones((n_frames, len(names)), dtype=bool)
    if max_height is not None:
        allowed = pos[..., 1] <= float(max_height)
    # still[s, k]: the window of lengths[s] frames from s stays within tolerance of its mean, the anchor
    still = np.zeros((n_frames, len(names)), dtype=bool)
    anchors = np.zeros((n_frames, len(names), 3))
    for window in np.unique(lengths):
        if n_frames < window:
            continue
        rows = np.flatnonzero(lengths[: n_frames - window + 1] == window)
        if rows.size == 0:
            continue
        # (W, n, 3, window): every window of every joint at once
        windows = np.lib.stride_tricks.sliding_window_view(pos, window, axis=0)
        ok_window = np.lib.stride_tricks.sliding_window_view(allowed, window, axis=0)
        if rows.size < windows.shape[0]:
            windows, ok_window = windows[rows], ok_window[rows]
        anchor = windows.mean(axis=-1)  # (W, n, 3)
        spread = np.linalg.norm(windows - anchor[..., None], axis=2).max(axis=-1)  # (W, n)
        still[rows] = (spread <= tolerance) & ok_window.all(axis=-1)
        anchors[rows] = anchor
    for k in range(len(names)):
        starts = np.flatnonzero(still[:, k])
        done = 0  # frames before `done` belong to earlier contacts or were searched
        while True:
            starts = starts[starts >= done]
            if starts.size == 0:
                break
            s = int(starts[0])
            window = int(lengths[s])
            anchor = anchors[s, k]
            inside = (np.linalg.norm(pos[:, k] - anchor, axis=-1) <= tolerance) & allowed[:, k]
            outside_after = np.flatnonzero(~inside[s + window :])
            stop = s + window + int(outside_after[0]) if outside_after.size else n_frames
            outside_before = np.flatnonzero(~inside[done:s])
            start = done + int(outside_before[-1]) + 1 if outside_before.size else done
            mask[start:stop, k] = True
            done = stop
    return Contacts(names, mask, motion.fps)


def _gait_windows(motion: Motion, travel: float, cap: float = 0.25) -> NDArray[np.int64]:
    """Frames a still window starting at each frame must last, scaled to the gait, shape (F,).

    ``min(cap, travel / v)`` seconds (at least 2 frames), ``v`` the pelvis's
    mean horizontal speed over the ``cap`` seconds from that frame (Y up).
    """
    fps = motion.fps
    longest = max(2, _frames(cap, fps, "min_duration"))
    p = np.asarray(motion.pelvis_positions)[:, [0, 2]]
    n = p.shape[0]
    if n < 2:
        return np.full(n, longest)
    speed = np.linalg.norm(np.gradient(p, axis=0), axis=-1) * fps  # (F,) m/s
    c = np.concatenate([[0.0], np.cumsum(speed)])
    stop = np.minimum(np.arange(n) + longest, n)
    mean = (c[stop] - c[np.arange(n)]) / (stop - np.arange(n))
    seconds = np.minimum(cap, travel / np.maximum(mean, 1e-9))
    return np.clip(np.round(seconds * fps).astype(np.int64), 2, longest)


# --------------------------------------------------------------------------
# the floor the feet stand on
# --------------------------------------------------------------------------
#: Horizontal spread (metres, standard deviation of the planted samples) below
#: which a floor's slope cannot be told from capture noise: the floor is
#: taken as level.
FLOOR_SLOPE_SPREAD = 0.5


@dataclasses.dataclass(frozen=True)
class Floor:
    """The ground plane the feet stand on, and each foot joint's height above it when planted.

    The plane is ``y = slope[0] * x + slope[1] * z`` plus each joint's own
    level: joint ``joints[k]`` rests at ``slope . (x, z) + levels[k]`` when
    planted (an ankle some centimetres above a toe joint), so
    :meth:`depth` is how far a joint is below where it would stand.
    :func:`estimate_floor` fits one to a motion's planted frames.

    Parameters
    ----------
    joints : tuple of str
        The foot joints.
    slope : ndarray, shape (2,)
        Rise of the floor per metre along x and along z (0 for a level floor).
    levels : ndarray, shape (n,)
        Height of each joint above ``slope . (x, z)`` when planted, metres.
    ground : float
        Height of the ground surface above ``slope . (x, z)``, metres: where
        the soles are (the ZMP's plane in :func:`mocaplab.physics.balance`,
        which fills it in from the feet's support points); 0 by default.

    Examples
    --------
    >>> floor = Floor(("LeftFoot",), [0.0, 0.1], [0.08])
    >>> round(floor.angle, 2), floor.describe()
    (5.71, 'floor inclined 5.7 deg; planted heights LeftFoot 80 mm')
    """

    joints: tuple[str, ...]
    slope: NDArray[np.float64]
    levels: NDArray[np.float64]
    ground: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "joints", tuple(self.joints))
        object.__setattr__(self, "slope", readonly(np.array(self.slope, dtype=float)))
        object.__setattr__(self, "levels", readonly(np.array(self.levels, dtype=float)))
        object.__setattr__(self, "ground", float(self.ground))

    @property
    def angle(self) -> float:
        """Steepest inclination of the floor, degrees."""
        return float(np.degrees(np.arctan(np.linalg.norm(self.slope))))

    def depth(self, motion: Motion) -> NDArray[np.float64]:
        """How far each joint is below its planted height on every frame, metres, shape (F, n) (negative above)."""
        idx = [motion.skeleton.index(j) for j in self.joints]
        p = motion.global_positions()[:, idx]
        return p[..., [0, 2]] @ self.slope + self.levels - p[..., 1]

    def describe(self) -> str:
        """One line: the slope and the planted heights."""
        levels = ", ".join(f"{j} {1000 * h:.0f} mm" for j, h in zip(self.joints, self.levels, strict=True))
        return f"floor inclined {self.angle:.1f} deg; planted heights {levels}"


def _fit_slope(pos: NDArray[np.float64], mask: NDArray[np.bool_]) -> NDArray[np.float64]:
    """Least-squares slope (2,) of a plane with one height per column through ``pos[mask]`` ((F, n, 3), (F, n)).

    Only along the horizontal directions the samples spread over by at least
    :data:`FLOOR_SLOPE_SPREAD` (see :func:`estimate_floor`).
    """
    frames, cols = np.nonzero(mask)
    samples = pos[frames, cols]
    onehot = np.zeros((len(frames), pos.shape[1]))
    onehot[np.arange(len(frames)), cols] = 1.0
    # the slope only along horizontal directions the planted samples spread over
    # (a straight walk says nothing about the floor's tilt across its path)
    xz = samples[:, [0, 2]] - samples[:, [0, 2]].mean(axis=0)
    var, vecs = np.linalg.eigh(xz.T @ xz / len(xz))
    dirs = vecs[:, np.sqrt(np.maximum(var, 0.0)) >= FLOOR_SLOPE_SPREAD]  # (2, d), d in 0..2
    used = onehot.any(axis=0)
    design = np.column_stack([xz @ dirs, onehot[:, used]])
    coef = np.linalg.lstsq(design, samples[:, 1], rcond=None)[0]
    return dirs @ coef[: dirs.shape[1]]


def estimate_floor(
    motion: Motion, contacts: Contacts, *, percentile: float = 5.0
) -> Floor | None:
    """The floor a motion's feet stand on, fitted to its planted frames.

    A least-squares plane ``y = a x + b z + c_k`` through the positions of
    the contact joints on their planted frames, with one height ``c_k`` per
    joint (joints rest at different heights above the sole).  The slope is
    fitted only along the horizontal directions over which the planted
    samples spread by at least :data:`FLOOR_SLOPE_SPREAD` metres (standard
    deviation): along a straight walk but not across it, and not for a dance
    on the spot, where the floor is taken as level; a slope within
    :data:`LEVEL_FLOOR_ANGLE` (2 degrees) is taken as level too (see there:
    one take cannot tell a stage's tilt from a drift of the planted heights).
    Each joint's level is then the
    ``percentile`` percentile of its heights above the plane while planted,
    so capture noise leaves only a few planted frames below the floor.

    Parameters
    ----------
    motion : Motion
    contacts : Contacts
        Planted joints, over the motion's frames.
    percentile : float
        See above (0-100).

    Returns
    -------
    Floor, or None when no joint is ever planted.

    Examples
    --------
    >>> import numpy as np
    >>> from mocaplab import Motion, Skeleton
    >>> sk = Skeleton(["foot"], [-1], [[0, 0, 0]])
    >>> root = np.column_stack([np.linspace(0, 3, 4), np.linspace(0, 0.3, 4), np.zeros(4)])
    >>> m = Motion(sk, np.tile([0, 0, 0, 1.0], (4, 1, 1)), root, 30)
    >>> floor = estimate_floor(m, Contacts(("foot",), np.ones((4, 1), bool), 30))
    >>> round(float(floor.slope[0]), 6), round(floor.angle, 2)
    (0.1, 5.71)
    """
    if contacts.n_frames != motion.n_frames:
        raise ValueError(f"Expected contacts over {motion.n_frames} frames, got {contacts.n_frames}")
    if not 0.0 <= percentile <= 100.0:
        raise ValueError(f"Expected `percentile` in [0, 100], got {percentile!r}")
    if not contacts.mask.any():
        return None
    idx = [motion.skeleton.index(j) for j in contacts.joints]
    pos = motion.global_positions()[:, idx]
    n = len(contacts.joints)
    slope = _levelled(_fit_slope(pos, contacts.mask))
    above = pos[..., 1] - pos[..., [0, 2]] @ slope  # (F, n) heights above the plane
    levels = np.empty(n)
    for k in range(n):
        planted = contacts.mask[:, k]
        levels[k] = np.percentile(above[planted, k] if planted.any() else above[:, k], percentile)
    return Floor(tuple(contacts.joints), slope, levels)
