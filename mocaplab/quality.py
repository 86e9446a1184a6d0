"""Measures of what a motion looks like, and of what an edit did to it.

Every method in mocaplab returns a motion that somebody will watch.  The
residuals a method minimises (pins met, ZMP inside the polygon) say nothing of
the artefacts it may add on the way: feet that slide, a pelvis that jumps in
one frame, a knee that bends the other way.  This module measures those
artefacts on any motion, independently of how it was made, and compares an
output with its input, since real captures have artefacts of their own (a
capture's feet slide a few millimetres per frame; its knees are noisy at
120 fps): an edit is judged by the ratio of each measure to the input's own.

Measures (units as in the report; every distance in millimetres whatever the
file's unit, since a :class:`~mocaplab.motion.Motion` is in metres):

``skate``
    Foot skate: the horizontal slide of the planted foot joints (ankles and
    toes, from the roles) between consecutive frames on which both are
    planted, **mm per frame** at the clip's rate; the mean over planted frames
    (``skate``) and the largest (``skate_max``).  Contacts are the *input's*
    (:func:`mocaplab.contacts.foot_contacts`): a foot planted in the input
    that slides in the output counts, even where a detector run on the output
    would no longer call it planted.
``penetration``
    The deepest a foot joint goes below the floor the feet stand on, mm.  The
    floor is the input's (:func:`mocaplab.contacts.estimate_floor`: a plane,
    level or sloped, and each foot joint's height above it when planted).
``displacement``
    Pops: the largest one-frame displacement of each joint, mm per frame;
    the report names the joint with the largest value (one motion) or the
    largest ratio to the input's own (an edit).
``angular_acceleration``
    Pops in rotation: the peak angular acceleration of each joint's local
    rotation, rad/s^2 (second difference of the rotation over frames).
``bone_drift``
    The largest change of a bone's length (joint to parent), mm, against the
    input's length, over the bones the input keeps rigid (length range within
    :data:`RIGID_BONE`): bones the input animates (a pelvis translating below
    a static root, stretchy rigs) are left out.  Zero for one motion measured
    against itself unless a rigid bone varies by up to 1 mm.
``hinge_flips``
    Frames on which a knee or elbow bends the other way: the bend about the
    axis the input bends about (its bend-weighted mean, in the frame of the
    upper bone's joint), that is the bend angle times the cosine between
    the frame's own axis ``(upper bone x lower bone)`` and that one, is at
    least :data:`FLIP_MIN_BEND` degrees the other way.  A straight limb has
    no axis and never counts, nor does a bend about an axis near
    perpendicular to the hinge (a near-straight elbow's axis is mostly the
    capture's noise: bent 18 degrees about an axis 91 degrees off the hinge
    is not bent backwards).
``zmp``
    Mean distance of the ZMP outside the support polygon over the ground
    frames, mm (:func:`mocaplab.physics.zmp.balance`, the input's contacts).
``static_root``
    How far the channels of a static reference root moved, mm and degrees:
    0 for a root that stays put; ``nan`` when the input's root is not static.

Where a measure cannot be taken (a skeleton without feet has no skate; no
knees, no flips) its value is ``nan`` and the report says why.

Examples
--------
>>> import mocaplab as ml
>>> walk = ml.cmu("16_15")[:120]
>>> report = ml.quality.compare(walk, ml.refine(walk))
>>> round(report["skate"].before, 1), report["skate"].ratio < 0.7  # the feet still roll on and off
(1.4, True)

Longer than 800 lines because every measure, its limit and the report that compares them are one instrument, documented with worked examples.
"""

from __future__ import annotations

import dataclasses
import html
import math
from collections.abc import Iterator, Mapping, Sequence
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from . import quat
from .contacts import Contacts, Floor, estimate_floor, foot_contacts
from .motion import Motion
from .roles import RolesError, resolve_roles

__all__ = [
    "Limit",
    "LIMITS",
    "FLIP_MIN_BEND",
    "RIGID_BONE",
    "Measure",
    "Quality",
    "Row",
    "Comparison",
    "measure",
    "compare",
    "skate",
    "penetration",
    "displacement",
    "angular_acceleration",
    "bone_lengths",
    "hinge_axes",
    "hinge_flips",
]

Array = NDArray[np.float64]

#: A bone whose length varies by less than this over the input (metres) is
#: rigid: its drift in an output is measured.
RIGID_BONE = 1e-3

#: A limb bent by less than this (degrees) has no defined hinge axis: it is
#: straight, and its bend direction is not counted as a flip.
FLIP_MIN_BEND = 15.0


@dataclasses.dataclass(frozen=True)
class Limit:
    """When an output's measure counts as a regression: ``after > factor * before + slack``.

    Parameters
    ----------
    factor : float
        Allowed ratio to the input's own value.
    slack : float
        Allowed absolute excess, in the measure's unit (so an input with
        almost none of an artefact may gain a little).

    Examples
    --------
    >>> Limit(1.5, 2.0).exceeded(10.0, 16.0), Limit(1.5, 2.0).exceeded(10.0, 18.0)
    (False, True)
    """

    factor: float
    slack: float

    def exceeded(self, before: float, after: float) -> bool:
        if not (np.isfinite(before) and np.isfinite(after)):
            return False
        return after > self.factor * before + self.slack


#: Default limits of :meth:`Comparison.regressions`, per measure.  Reasons:
#: skate and penetration may grow by half (a bend moves planted feet; the
#: foot solver cleans up after) plus a small absolute amount; a pop is a joint
#: moving more in one frame than 1.5 times its own largest move plus 2 mm; an
#: angular acceleration may double (re-timing speeds joints up); bones are
#: rigid, so any drift beyond 1 mm is a fault; no new flipped hinge frame; the
#: ZMP may move out by half again plus 5 mm; a static root stays static.
LIMITS: Mapping[str, Limit] = {
    "skate": Limit(1.5, 0.5),
    "skate_max": Limit(2.0, 2.0),
    "penetration": Limit(1.5, 5.0),
    "displacement": Limit(1.5, 2.0),
    "angular_acceleration": Limit(2.0, 20.0),
    "bone_drift": Limit(1.0, 1.0),
    "hinge_flips": Limit(1.0, 0.0),
    "zmp": Limit(1.5, 5.0),
    "static_root": Limit(1.0, 1e-3),
}

_UNITS = {
    "skate": "mm/frame",
    "skate_max": "mm/frame",
    "penetration": "mm",
    "displacement": "mm/frame",
    "angular_acceleration": "rad/s^2",
    "bone_drift": "mm",
    "hinge_flips": "frames",
    "zmp": "mm",
    "static_root": "mm",
}
_ORDER = tuple(_UNITS)


# --------------------------------------------------------------------------
# the measures, one function each
# --------------------------------------------------------------------------
def _check_motion(motion: Any, what: str = "motion") -> Motion:
    if not isinstance(motion, Motion):
        raise TypeError(f"Expected `{what}` to be a Motion, got {type(motion).__name__}")
    return motion


def skate(motion: Motion, contacts: Contacts) -> Array:
    """Horizontal slide of the planted joints, mm per frame, shape (F - 1,).

    Entry ``i`` is the largest ground-plane distance ``|p(i+1) - p(i)|``
    over the joints of ``contacts`` planted on both frames ``i`` and
    ``i + 1``; NaN where none is.  The ground plane is (x, z) (Y up).

    Parameters
    ----------
    motion : Motion
    contacts : Contacts
        The planted joints, over the motion's frames.

    Returns
    -------
    ndarray, shape (F - 1,)
        Millimetres per frame; NaN on steps with no joint planted on both frames.

    Raises
    ------
    ValueError
        If ``contacts`` covers another number of frames.

    Examples
    --------
    >>> import numpy as np
    >>> from mocaplab import Motion, Skeleton
    >>> from mocaplab.contacts import Contacts
    >>> sk = Skeleton(["foot"], [-1], [[0, 0, 0]])
    >>> m = Motion(sk, np.tile([0, 0, 0, 1.0], (3, 1, 1)), [[0, 0, 0], [0.01, 0, 0], [0.02, 0, 0]], 30)
    >>> skate(m, Contacts(("foot",), np.ones((3, 1), bool), 30)).round(3).tolist()
    [10.0, 10.0]
    """
    return contacts.slide(_check_motion(motion))


def penetration(motion: Motion, floor: Floor) -> Array:
    """Depth of the deepest foot joint below the floor on each frame, mm, shape (F,); 0 above it.

    ``floor`` gives each foot joint's height above the floor plane when
    planted (:func:`mocaplab.contacts.estimate_floor`); a joint lower than
    that is below the floor by the difference.

    Parameters
    ----------
    motion : Motion
    floor : Floor
        The floor and the planted heights of its joints.

    Returns
    -------
    ndarray, shape (F,)
        Millimetres below the floor, 0 where every foot joint is at or above it.

    Examples
    --------
    >>> import numpy as np
    >>> from mocaplab import Motion, Skeleton
    >>> from mocaplab.contacts import Contacts, estimate_floor
    >>> sk = Skeleton(["foot"], [-1], [[0, 0, 0]])
    >>> m = Motion(sk, np.tile([0, 0, 0, 1.0], (3, 1, 1)), [[0, 0, 0], [0, 0, 0], [0, -0.02, 0]], 30)
    >>> floor = estimate_floor(m, Contacts(("foot",), np.array([[1], [1], [0]], bool), 30))
    >>> penetration(m, floor).round(3).tolist()
    [0.0, 0.0, 20.0]
    """
    motion = _check_motion(motion)
    depth = floor.depth(motion)
    return np.maximum(depth.max(axis=1), 0.0) * 1000.0


def displacement(motion: Motion) -> Array:
    """Largest one-frame displacement of each joint, mm per frame, shape (J,) (zeros for one frame).

    Parameters
    ----------
    motion : Motion

    Returns
    -------
    ndarray, shape (J,)
        Millimetres per frame, in skeleton order.

    Examples
    --------
    >>> import numpy as np
    >>> from mocaplab import Motion, Skeleton
    >>> sk = Skeleton(["root", "tip"], [-1, 0], [[0, 0, 0], [0, 1, 0]])
    >>> m = Motion(sk, np.tile([0, 0, 0, 1.0], (4, 2, 1)), [[0, 0, 0], [0, 0, 0], [0.05, 0, 0], [0.05, 0, 0]], 30)
    >>> displacement(m).round(3).tolist()
    [50.0, 50.0]
    """
    motion = _check_motion(motion)
    if motion.n_frames < 2:
        return np.zeros(motion.n_joints)
    steps = np.linalg.norm(np.diff(motion.global_positions(), axis=0), axis=-1)
    return steps.max(axis=0) * 1000.0


def angular_acceleration(motion: Motion) -> Array:
    """Peak angular acceleration of each joint's local rotation, rad/s^2, shape (J,).

    The angular velocity between frames ``i`` and ``i + 1`` is the rotation
    vector of ``q_i^-1 q_{i+1}`` times the frame rate (in the joint's own
    frame); its change between consecutive steps times the frame rate is the
    acceleration.  Zeros for clips shorter than 3 frames.

    Parameters
    ----------
    motion : Motion

    Returns
    -------
    ndarray, shape (J,)
        Radians per second squared, in skeleton order.

    Examples
    --------
    A joint turning by 0, 0.1 then 0.2 rad per frame at 30 fps speeds up by
    3 rad/s each frame, 90 rad/s^2:

    >>> import numpy as np
    >>> from mocaplab import Motion, Skeleton
    >>> sk = Skeleton(["root", "tip"], [-1, 0], [[0, 0, 0], [0, 1, 0]])
    >>> half = np.array([0.0, 0.0, 0.1, 0.3]) / 2
    >>> rot = np.tile([0, 0, 0, 1.0], (4, 2, 1))
    >>> rot[:, 1, 2], rot[:, 1, 3] = np.sin(half), np.cos(half)
    >>> angular_acceleration(Motion(sk, rot, np.zeros((4, 3)), 30)).round(3).tolist()
    [0.0, 90.0]
    """
    motion = _check_motion(motion)
    if motion.n_frames < 3:
        return np.zeros(motion.n_joints)
    q = motion.rotations
    omega = quat.log(quat.mul(quat.inv(q[:-1]), q[1:])) * motion.fps
    acc = np.linalg.norm(np.diff(omega, axis=0), axis=-1) * motion.fps
    return acc.max(axis=0)


def bone_lengths(motion: Motion) -> Array:
    """Length of every bone (joint to its parent) on every frame, metres, shape (F, J); column 0 is 0.

    Parameters
    ----------
    motion : Motion

    Returns
    -------
    ndarray, shape (F, J)
        Metres; column ``j`` is the distance from joint ``j`` to its parent.

    Examples
    --------
    >>> import numpy as np
    >>> from mocaplab import Motion, Skeleton
    >>> sk = Skeleton(["root", "tip"], [-1, 0], [[0, 0, 0], [0, 1, 0]])
    >>> bone_lengths(Motion(sk, np.tile([0, 0, 0, 1.0], (4, 2, 1)), np.zeros((4, 3)), 30))[0].tolist()
    [0.0, 1.0]
    """
    motion = _check_motion(motion)
    gpos = motion.global_positions()
    parents = motion.skeleton.parents
    out = np.zeros((motion.n_frames, motion.n_joints))
    out[:, 1:] = np.linalg.norm(gpos[:, 1:] - gpos[:, parents[1:]], axis=-1)
    return out


def _hinges(motion: Motion, roles: Mapping[str, Any] | None) -> list[tuple[str, int, int, int]]:
    """``(label, upper, middle, lower)`` joint indices of the knees and elbows the roles give."""
    try:
        known = resolve_roles(motion, roles)
    except RolesError:
        return []
    out: list[tuple[str, int, int, int]] = []
    limbs: tuple[tuple[Literal["leg", "arm"], str], ...] = (("leg", "knee"), ("arm", "elbow"))
    for limb, label in limbs:
        for side in ("left", "right"):
            try:
                upper, middle, lower = (motion.skeleton.index(n) for n in known.limb(side, limb))
            except RolesError:
                continue
            out.append((f"{side}_{label}", upper, middle, lower))
    return out


def _bend(motion: Motion, upper: int, middle: int, lower: int) -> tuple[Array, Array]:
    """Hinge axes in the upper joint's frame (F, 3), unit or zero, and bend angles in degrees (F,)."""
    grot, gpos = motion.global_rotations(), motion.global_positions()
    a = gpos[:, middle] - gpos[:, upper]
    b = gpos[:, lower] - gpos[:, middle]
    axis = np.cross(a, b)
    norm = np.linalg.norm(axis, axis=-1)
    lengths = np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1)
    bend = np.degrees(np.arctan2(norm, np.einsum("fi,fi->f", a, b)))
    unit = np.where(norm[:, None] > 1e-12 * np.maximum(lengths, 1e-30)[:, None], axis, 0.0)
    unit = unit / np.maximum(np.linalg.norm(unit, axis=-1, keepdims=True), 1e-300)
    return quat.rotate(quat.inv(grot[:, upper]), unit), bend


def hinge_axes(motion: Motion, *, roles: Mapping[str, Any] | None = None) -> dict[str, Array]:
    """The axis each knee and elbow bends about, in the frame of its upper joint (hip, shoulder).

    The bend-weighted mean over the clip of the per-frame hinge axis
    ``(middle - upper) x (lower - middle)``, normalised: a unit vector per
    hinge, shape (3,).  A hinge that never bends beyond
    :data:`FLIP_MIN_BEND` is left out.

    Parameters
    ----------
    motion : Motion
    roles : mapping, optional
        Role overrides (:func:`mocaplab.roles.resolve_roles`); default the
        roles inferred from the joint names and topology.

    Returns
    -------
    dict of str to ndarray, shape (3,)
        ``{"left_knee": axis, ...}``; empty when the roles give no limbs.

    Examples
    --------
    >>> import mocaplab as ml
    >>> axes = hinge_axes(ml.cmu("16_15"))
    >>> sorted(axes), axes["left_knee"].round(2).tolist()
    (['left_elbow', 'left_knee', 'right_elbow', 'right_knee'], [0.94, 0.34, -0.0])
    """
    motion = _check_motion(motion)
    out = {}
    for label, upper, middle, lower in _hinges(motion, roles):
        axes, bend = _bend(motion, upper, middle, lower)
        weight = np.where(bend >= FLIP_MIN_BEND, bend, 0.0)
        mean = (axes * weight[:, None]).sum(axis=0)
        if np.linalg.norm(mean) > 0:
            out[label] = mean / np.linalg.norm(mean)
    return out


def hinge_flips(
    motion: Motion, axes: Mapping[str, Array] | None = None, *, roles: Mapping[str, Any] | None = None
) -> dict[str, int]:
    """Frames on which each knee and elbow bends against its axis, ``{hinge: count}``.

    Parameters
    ----------
    motion : Motion
    axes : mapping of hinge label to ndarray, shape (3,), optional
        The bend axes to test against (:func:`hinge_axes`, usually the
        input's); default the motion's own.
    roles : mapping, optional
        Role overrides (:func:`mocaplab.roles.resolve_roles`).

    Returns
    -------
    dict of str to int
        Per hinge with an axis, the frames bent by at least
        :data:`FLIP_MIN_BEND` degrees the other way about it (the bend's
        component about the axis).

    Examples
    --------
    A walk never bends a knee backwards; against reversed axes every bent
    frame counts:

    >>> import mocaplab as ml
    >>> walk = ml.cmu("16_15")
    >>> hinge_flips(walk)["left_knee"]
    0
    >>> axes = hinge_axes(walk)
    >>> hinge_flips(walk, {k: -v for k, v in axes.items()})["right_knee"], walk.n_frames
    (415, 471)
    """
    motion = _check_motion(motion)
    axes = hinge_axes(motion, roles=roles) if axes is None else axes
    out = {}
    for label, upper, middle, lower in _hinges(motion, roles):
        if label not in axes:
            continue
        local, bend = _bend(motion, upper, middle, lower)
        against = bend * (local @ np.asarray(axes[label], dtype=float)) <= -FLIP_MIN_BEND
        out[label] = int(np.count_nonzero(against))
    return out


def _static_root(motion: Motion) -> bool:
    """True when joint 0's channels never change over the clip (a static reference root)."""
    if motion.n_frames < 2:
        return False
    rot = np.ptp(motion.rotations[:, 0], axis=0).max()
    pos = np.ptp(motion.root_positions, axis=0).max()
    return bool(rot < 1e-9 and pos < 1e-9)


def _root_change(before: Motion, after: Motion) -> float:
    """How far joint 0 of ``after`` strays from the static root of ``before``, mm (rotations as mm at 1 m)."""
    ref_pos, ref_rot = before.root_positions[0], before.rotations[0, 0]
    pos = np.linalg.norm(after.root_positions - ref_pos, axis=-1).max()
    ang = quat.angle(quat.mul(quat.inv(ref_rot), after.rotations[:, 0])).max()
    return float(max(pos, ang) * 1000.0)


# --------------------------------------------------------------------------
# one motion
# --------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Measure:
    """One measure of one motion.

    Parameters
    ----------
    name : str
        The measure (see the module docstring).
    unit : str
        Its unit, e.g. ``"mm/frame"``.
    value : float
        ``nan`` when it cannot be taken (see ``note``).
    where : str, default ""
        The joint, hinge or frame the value comes from ("" when global).
    note : str, default ""
        Why a value is missing, or what it was measured against.

    Examples
    --------
    >>> Measure("penetration", "mm", 3.5, "frame 12").value
    3.5
    """

    name: str
    unit: str
    value: float
    where: str = ""
    note: str = ""


def _table(header: Sequence[str], rows: Sequence[Sequence[str]], title: str) -> str:
    widths = [max(len(h), *(len(r[k]) for r in rows)) if rows else len(h) for k, h in enumerate(header)]
    line = "  ".join(h.ljust(w) for h, w in zip(header, widths, strict=True))
    body = ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows]
    return "\n".join([title, line, "  ".join("-" * w for w in widths), *body])


def _html_table(header: Sequence[str], rows: Sequence[Sequence[str]], title: str, marks: Sequence[bool]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join(
        "<tr{}>{}</tr>".format(
            ' style="background:#fde2e2"' if bad else "", "".join(f"<td>{html.escape(c)}</td>" for c in r)
        )
        for r, bad in zip(rows, marks, strict=True)
    )
    return f"<div><b>{html.escape(title)}</b><table><tr>{head}</tr>{body}</table></div>"


def _by_name(entries: Sequence[Any], name: str) -> Any:
    """The entry of a report called ``name`` (KeyError listing the measures)."""
    for entry in entries:
        if entry.name == name:
            return entry
    raise KeyError(f"No measure {name!r}; measures are {[e.name for e in entries]}")


def _fmt(value: float) -> str:
    if not np.isfinite(value):
        return "nan" if np.isnan(value) else ("inf" if value > 0 else "-inf")
    if value == int(value) and abs(value) < 1e6:
        return f"{int(value)}"
    return f"{value:.3g}" if abs(value) < 100 else f"{value:.0f}"


@dataclasses.dataclass(frozen=True)
class Quality:
    """The measures of one motion (:func:`measure`): ``report["skate"].value``.

    Parameters
    ----------
    name : str
        The motion's name.
    measures : tuple of Measure
        In the order of the module docstring.

    Examples
    --------
    >>> import numpy as np
    >>> from mocaplab import Motion, Skeleton
    >>> sk = Skeleton(["root", "tip"], [-1, 0], [[0, 0, 0], [0, 1, 0]])
    >>> report = measure(Motion(sk, np.tile([0, 0, 0, 1.0], (4, 2, 1)), np.zeros((4, 3)), 30), contacts=None)
    >>> [m.name for m in report][:4], report["bone_drift"].value
    (['skate', 'skate_max', 'penetration', 'displacement'], 0.0)
    """

    name: str
    measures: tuple[Measure, ...]

    def __getitem__(self, name: str) -> Measure:
        return _by_name(self.measures, name)

    def __iter__(self) -> Iterator[Measure]:
        return iter(self.measures)

    def _rows(self) -> list[list[str]]:
        return [[m.name, _fmt(m.value), m.unit, m.where, m.note] for m in self.measures]

    def __repr__(self) -> str:
        return _table(("measure", "value", "unit", "where", "note"), self._rows(), f"Quality of {self.name!r}")

    def _repr_html_(self) -> str:
        rows = self._rows()
        return _html_table(("measure", "value", "unit", "where", "note"), rows, f"Quality of {self.name!r}",
                           [False] * len(rows))


@dataclasses.dataclass(frozen=True)
class _Reference:
    """What the measures of a motion are taken against: contacts, floor, hinge axes, bones, balance."""

    contacts: Contacts | None
    floor: Floor | None
    axes: dict[str, Array]
    bones: Array | None
    why: str


def _reference(motion: Motion, contacts: Contacts | Literal["auto"] | None, roles: Mapping[str, Any] | None) -> _Reference:
    why = ""
    found: Contacts | None
    if contacts == "auto":
        try:
            found = foot_contacts(motion, roles=roles)
        except RolesError as exc:
            found, why = None, f"no feet: {exc}".split("\n")[0]
    elif contacts is None:
        found, why = None, "contacts=None"
    elif isinstance(contacts, Contacts):
        found = contacts
    else:
        raise TypeError(f"Expected `contacts` to be 'auto', None or a Contacts, got {type(contacts).__name__}")
    if found is not None and found.n_frames != motion.n_frames:
        raise ValueError(f"Expected `contacts` over {motion.n_frames} frames, got {found.n_frames}")
    floor = None
    if found is not None:
        floor = estimate_floor(motion, found)
        if floor is None:
            why = "no planted frame"
    lengths = bone_lengths(motion)
    rigid = np.ptp(lengths, axis=0) <= RIGID_BONE
    bones = np.where(rigid, np.median(lengths, axis=0), np.nan)  # NaN: a bone the input animates
    return _Reference(found, floor, hinge_axes(motion, roles=roles), bones, why)


def _zmp_mm(motion: Motion, contacts: Contacts | None, roles: Mapping[str, Any] | None) -> tuple[float, str]:
    if contacts is None or not contacts.mask.any():
        return math.nan, "no contacts"
    from .physics.zmp import balance

    try:
        return balance(motion, contacts=contacts, roles=roles).mean_distance * 1000.0, ""
    except RolesError as exc:
        return math.nan, f"no body: {str(exc).splitlines()[0]}"


def _measures(
    motion: Motion, ref: _Reference, roles: Mapping[str, Any] | None, *, static_before: Motion | None
) -> dict[str, Measure]:
    names = motion.skeleton.names
    out: dict[str, Measure] = {}
    same = ref.contacts is not None and ref.contacts.n_frames == motion.n_frames
    contacts = ref.contacts if same else None
    note = ref.why
    if ref.contacts is not None and not same:
        try:
            contacts = foot_contacts(motion, roles=roles)
            note = "contacts detected on this motion (frame count differs from the input's)"
        except RolesError:
            contacts = None
    if contacts is not None:
        s = skate(motion, contacts)
        ok = np.isfinite(s)
        mean = float(s[ok].mean()) if ok.any() else 0.0
        peak = float(s[ok].max()) if ok.any() else 0.0
        at = f"frame {int(np.flatnonzero(ok)[np.argmax(s[ok])])}" if ok.any() else ""
        out["skate"] = Measure("skate", _UNITS["skate"], mean, "", note)
        out["skate_max"] = Measure("skate_max", _UNITS["skate_max"], peak, at, note)
    else:
        out["skate"] = Measure("skate", _UNITS["skate"], math.nan, "", note or "no contacts")
        out["skate_max"] = Measure("skate_max", _UNITS["skate_max"], math.nan, "", note or "no contacts")
    if ref.floor is not None:
        depth = penetration(motion, ref.floor)
        i = int(np.argmax(depth))
        out["penetration"] = Measure("penetration", "mm", float(depth[i]), f"frame {i}", ref.floor.describe())
    else:
        out["penetration"] = Measure("penetration", "mm", math.nan, "", ref.why or "no floor")
    disp = displacement(motion)
    j = int(np.argmax(disp))
    out["displacement"] = Measure("displacement", _UNITS["displacement"], float(disp[j]), names[j])
    acc = angular_acceleration(motion)
    j = int(np.argmax(acc))
    out["angular_acceleration"] = Measure("angular_acceleration", _UNITS["angular_acceleration"], float(acc[j]), names[j])
    drift = None
    if ref.bones is not None:
        diff = np.abs(bone_lengths(motion) - ref.bones)
        drift = np.where(np.isnan(ref.bones), 0.0, np.nan_to_num(diff, nan=0.0).max(axis=0)) * 1000.0
    if drift is not None and drift.size:
        j = int(np.argmax(drift))
        out["bone_drift"] = Measure("bone_drift", "mm", float(drift[j]), names[j] if drift[j] > 0 else "")
    flips = hinge_flips(motion, ref.axes, roles=roles)
    if flips:
        worst = max(flips, key=lambda k: flips[k])
        total = float(sum(flips.values()))
        out["hinge_flips"] = Measure("hinge_flips", "frames", total, worst if total else "")
    else:
        out["hinge_flips"] = Measure("hinge_flips", "frames", math.nan, "", "no knees or elbows bend")
    zmp, why = _zmp_mm(motion, contacts, roles)
    out["zmp"] = Measure("zmp", "mm", zmp, "", why)
    base = static_before if static_before is not None else motion
    if _static_root(base):
        out["static_root"] = Measure("static_root", "mm", _root_change(base, motion), names[0])
    else:
        out["static_root"] = Measure("static_root", "mm", math.nan, "", "joint 0 is animated")
    return out


def measure(
    motion: Motion,
    *,
    contacts: Contacts | Literal["auto"] | None = "auto",
    roles: Mapping[str, Any] | None = None,
) -> Quality:
    """The artefact measures of one motion, against its own contacts, floor, hinges and bones.

    Parameters
    ----------
    motion : Motion
    contacts : "auto", None or Contacts
        Planted foot joints: ``"auto"`` detects them
        (:func:`mocaplab.contacts.foot_contacts`), ``None`` means none (no
        skate, penetration or ZMP), or give them.
    roles : mapping, optional
        Role overrides (:func:`mocaplab.roles.resolve_roles`).

    Returns
    -------
    Quality

    Examples
    --------
    >>> import numpy as np
    >>> from mocaplab import Motion, Skeleton
    >>> sk = Skeleton(["root", "tip"], [-1, 0], [[0, 0, 0], [0, 1, 0]])
    >>> m = Motion(sk, np.tile([0, 0, 0, 1.0], (4, 2, 1)), np.zeros((4, 3)), 30)
    >>> measure(m, contacts=None)["displacement"].value
    0.0
    """
    motion = _check_motion(motion)
    ref = _reference(motion, contacts, roles)
    return Quality(motion.name, tuple(_measures(motion, ref, roles, static_before=None).values()))


# --------------------------------------------------------------------------
# an edit: before and after
# --------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Row:
    """One measure of an edit: the input's value, the output's, their ratio and the verdict.

    Parameters
    ----------
    name, unit : str
        The measure and its unit.
    before, after : float
        The measure on the input and on the output, both against the
        input's contacts, floor, hinge axes and bone lengths.
    ratio : float
        ``after / before`` (``inf`` when only ``after`` has the artefact,
        ``1.0`` when neither has; for per-joint measures the largest ratio
        over the joints, with ``where`` naming the joint).
    limit : Limit
    regressed : bool
        ``after > limit.factor * before + limit.slack`` (for per-joint
        measures: on any joint).
    where, note : str, default ""
        The joint, hinge or frame of the value; why a value is missing.

    Examples
    --------
    >>> row = Row("skate", "mm/frame", 1.0, 3.0, 3.0, LIMITS["skate"], True)
    >>> row.regressed, row.limit.exceeded(row.before, row.after)
    (True, True)
    """

    name: str
    unit: str
    before: float
    after: float
    ratio: float
    limit: Limit
    regressed: bool
    where: str = ""
    note: str = ""


def _ratio(before: float, after: float) -> float:
    if not (np.isfinite(before) and np.isfinite(after)):
        return math.nan
    if before == 0.0:
        return 1.0 if after == 0.0 else math.inf
    return after / before


@dataclasses.dataclass(frozen=True)
class Comparison:
    """What an edit did to a motion (:func:`compare`): one :class:`Row` per measure.

    ``report["skate"].ratio``; :attr:`regressions` lists the rows beyond
    their limits; ``repr`` prints a table (``_repr_html_`` in notebooks,
    regressions marked).

    Parameters
    ----------
    before_name, after_name : str
        The names of the input and the output motions.
    rows : tuple of Row
        One per measure, in the order of the module docstring.

    Examples
    --------
    >>> import numpy as np
    >>> from mocaplab import Motion, Skeleton
    >>> sk = Skeleton(["root", "tip"], [-1, 0], [[0, 0, 0], [0, 1, 0]])
    >>> m = Motion(sk, np.tile([0, 0, 0, 1.0], (4, 2, 1)), np.zeros((4, 3)), 30)
    >>> report = compare(m, m, contacts=None)
    >>> report.ok, report["displacement"].ratio, report.regressions
    (True, 1.0, ())
    """

    before_name: str
    after_name: str
    rows: tuple[Row, ...]

    def __getitem__(self, name: str) -> Row:
        return _by_name(self.rows, name)

    def __iter__(self) -> Iterator[Row]:
        return iter(self.rows)

    @property
    def regressions(self) -> tuple[Row, ...]:
        """The rows whose output exceeds their :class:`Limit`."""
        return tuple(r for r in self.rows if r.regressed)

    @property
    def ok(self) -> bool:
        """No measure regressed."""
        return not self.regressions

    def _cells(self) -> list[list[str]]:
        return [
            [r.name, _fmt(r.before), _fmt(r.after), _fmt(r.ratio), r.unit, "REGRESSED" if r.regressed else "",
             r.where, r.note]
            for r in self.rows
        ]

    _HEADER = ("measure", "input", "output", "ratio", "unit", "", "where", "note")

    def _title(self) -> str:
        verdict = "no regression" if self.ok else f"{len(self.regressions)} regression(s)"
        return f"Quality of {self.after_name!r} against {self.before_name!r}: {verdict}"

    def __repr__(self) -> str:
        return _table(self._HEADER, self._cells(), self._title())

    def _repr_html_(self) -> str:
        return _html_table(self._HEADER, self._cells(), self._title(), [r.regressed for r in self.rows])


def _per_joint_row(name: str, before: Array, after: Array, names: Sequence[str], limit: Limit) -> Row:
    """A row over joints: the joint with the largest excess ratio ``(after + slack) / (before + slack)``."""
    slack = max(limit.slack, 1e-12)
    excess = (after + slack) / (before + slack)
    j = int(np.argmax(excess))
    bad = bool(np.any(after > limit.factor * before + limit.slack))
    return Row(name, _UNITS[name], float(before[j]), float(after[j]), _ratio(float(before[j]), float(after[j])),
               limit, bad, names[j])


def compare(
    before: Motion,
    after: Motion,
    *,
    contacts: Contacts | Literal["auto"] | None = "auto",
    roles: Mapping[str, Any] | None = None,
    limits: Mapping[str, Limit] | None = None,
) -> Comparison:
    """Measure what an edit did: each artefact of ``after`` against ``before``'s own.

    Both motions are measured against the input's contacts, floor, hinge
    axes and bone lengths (so a foot that slides where the input was
    planted counts, and a knee that bends against the input's axis is a
    flip).  When the frame counts differ (a time warp), skate and ZMP of the
    output use contacts detected on it, and the row says so.  Per-joint
    measures (displacement, angular acceleration) are compared joint by
    joint by name; the row shows the joint with the largest ratio.

    Parameters
    ----------
    before, after : Motion
        The input and the output of a method; the same joint names (the
        output's joints are matched to the input's by name).
    contacts : "auto", None or Contacts
        The input's planted foot joints (see :func:`measure`).
    roles : mapping, optional
        Role overrides.
    limits : mapping of str to Limit, optional
        Overrides of :data:`LIMITS`, per measure.

    Returns
    -------
    Comparison

    Examples
    --------
    >>> import numpy as np
    >>> from mocaplab import Motion, Skeleton
    >>> sk = Skeleton(["root", "tip"], [-1, 0], [[0, 0, 0], [0, 1, 0]])
    >>> m = Motion(sk, np.tile([0, 0, 0, 1.0], (4, 2, 1)), np.zeros((4, 3)), 30)
    >>> jump = m.replace(root_positions=[[0, 0, 0], [0, 0, 0], [0.05, 0, 0], [0.05, 0, 0]])
    >>> r = compare(m, jump, contacts=None)["displacement"]
    >>> round(r.after), r.regressed
    (50, True)
    """
    before = _check_motion(before, "before")
    after = _check_motion(after, "after")
    missing = sorted(set(before.skeleton.names) - set(after.skeleton.names))
    if missing:
        raise ValueError(f"Expected `after` to have the joints of `before`; it lacks {missing[:5]}")
    lim = dict(LIMITS)
    if limits is not None:
        unknown = sorted(set(limits) - set(LIMITS))
        if unknown:
            raise ValueError(f"Unknown measures in `limits`: {unknown}; measures are {list(LIMITS)}")
        lim.update(limits)
    # the output's joints in the input's order
    order = [after.skeleton.index(n) for n in before.skeleton.names]
    ref = _reference(before, contacts, roles)
    mb = _measures(before, ref, roles, static_before=None)
    bones = np.full(after.n_joints, np.nan)  # joints only the output has: not measured
    bones[order] = ref.bones
    ref_after = dataclasses.replace(ref, bones=bones)
    ma = _measures(after, ref_after, roles, static_before=before if _static_root(before) else None)
    rows = []
    names = before.skeleton.names
    for name in _ORDER:
        if name == "displacement":
            rows.append(_per_joint_row(name, displacement(before), displacement(after)[order], names, lim[name]))
            continue
        if name == "angular_acceleration":
            rows.append(
                _per_joint_row(name, angular_acceleration(before), angular_acceleration(after)[order], names, lim[name])
            )
            continue
        if name not in mb or name not in ma:
            continue
        b, a = mb[name], ma[name]
        bv, av = b.value, a.value
        if name == "static_root":
            bv = 0.0 if np.isfinite(av) else math.nan
        rows.append(
            Row(name, b.unit, bv, av, _ratio(bv, av), lim[name], lim[name].exceeded(bv, av), a.where or b.where,
                a.note or b.note)
        )
    return Comparison(before.name, after.name, tuple(rows))
