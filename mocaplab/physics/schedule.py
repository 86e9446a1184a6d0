"""The schedule of a physical touch-up (Shin, Kovar and Gleicher 2003, section 3.1).

A touch-up is a sequence of **adjustments** (a *schedule*).  Each adjustment
names three link sets (section 3.1): S1 is left alone, S2 is rotated, S3 is
carried along by S2 but keeps its global orientation; a time scale
``sigma`` and a damping factor ``rho``.  This module holds the adjustments
(:class:`Adjustment`, the paper's schedules of section 4.1 and
:func:`default_schedule`), the link sets they name (:func:`preset_mask`,
:func:`link_sets`) and the split of a clip into the two stages that obey
different laws (section 3.1: :func:`flight_stages`; every other frame with
a planted joint is a ground frame).

It is the bottom of the touch-up's modules and imports none of them:
:mod:`mocaplab.physics.adjust` moves the link sets,
:mod:`mocaplab.physics.ground` and :mod:`mocaplab.physics.flight` compute
each stage's adjustments (sections 3.3 and 3.4) and
:mod:`mocaplab.physics.touchup` runs the schedule.

Choices made where the paper leaves them open
---------------------------------------------
* Link sets are given by joint names (each name means the joint and its
  descendants) or presets ``"lower_body"``, ``"upper_body"``, ``"arms"``,
  ``"all"``, found from the joint roles of any skeleton (see
  :func:`preset_mask`; ``roles=`` overrides them); S3 overrides S2 and S1
  is everything else.  One rotation angle is shared by all parts of S2
  (e.g. both arms), each turning about its own top joint.
* Stretches without contact that touch the first or last frame of the clip
  are no flights (their take-off or landing is outside the clip:
  :func:`flight_stages`); a clip with no planted frame is an error.
* The default schedule for a clip with flights is the flight schedule and
  then the ground one (:func:`default_schedule`), so every pass ends with
  a ground pass that balances the take-off and landing windows again.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from functools import lru_cache
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import NDArray

from ..motion import Skeleton, readonly
from ..roles import Roles, RolesError, resolve_roles

if TYPE_CHECKING:  # pragma: no cover
    from ..contacts import Contacts

__all__ = [
    "Adjustment",
    "GROUND_SCHEDULE",
    "FLIGHT_SCHEDULE",
    "default_schedule",
    "LinkSets",
    "link_sets",
    "preset_mask",
    "flight_stages",
    "check_schedule",
]

Stage = Literal["ground", "flight"]


# ======================================================================
# schedules
# ======================================================================
@dataclasses.dataclass(frozen=True)
class Adjustment:
    """One step of a touch-up schedule.

    Parameters
    ----------
    s2 : tuple of str
        Rotated links: joint names (each with its descendants) or presets
        ``"lower_body"``, ``"upper_body"``, ``"arms"``, ``"all"``.
    s3 : tuple of str
        Links carried by S2 that keep their global orientation (empty in
        flight).  S1 is every joint in neither set.
    sigma : float
        Width of the smoothing kernel in seconds, > 0 (the paper's 40 frames at
        30 fps is 4/3 s).
    rho : float
        Damping factor in (0, 1]: the share of the computed adjustment used.
    stage : {"ground", "flight"}
        Which frames this adjustment corrects.
    label : str
        A short description for displays.

    Examples
    --------
    Rotate the lower body while the upper body keeps its global orientation:

    >>> from mocaplab.physics import Adjustment
    >>> step = Adjustment(("lower_body",), ("upper_body",))
    >>> step.stage, round(step.sigma, 3), step.rho
    ('ground', 1.333, 0.5)
    """

    s2: tuple[str, ...]
    s3: tuple[str, ...] = ()
    sigma: float = 40.0 / 30.0
    rho: float = 0.5
    stage: Stage = "ground"
    label: str = ""

    def __post_init__(self) -> None:
        s2 = (self.s2,) if isinstance(self.s2, str) else tuple(str(s) for s in self.s2)
        s3 = (self.s3,) if isinstance(self.s3, str) else tuple(str(s) for s in self.s3)
        if not s2:
            raise ValueError("Expected at least one joint name or preset in `s2`, got none")
        if not (np.isfinite(self.sigma) and self.sigma > 0):
            raise ValueError(
                f"Expected `sigma` > 0 seconds (the width of the smoothing kernel), got {self.sigma!r}: without "
                "smoothing the per-frame corrections jump from frame to frame, their accelerations throw the ZMP "
                "about and frames lose it (negative vertical force)"
            )
        if not (np.isfinite(self.rho) and 0 < self.rho <= 1):
            raise ValueError(f"Expected `rho` in (0, 1], got {self.rho!r}")
        if self.stage not in ("ground", "flight"):
            raise ValueError(f"Expected `stage` to be 'ground' or 'flight', got {self.stage!r}")
        if self.stage == "flight" and s3:
            raise ValueError(f"Expected an empty `s3` for a flight adjustment (section 3.4), got {s3}")
        object.__setattr__(self, "s2", s2)
        object.__setattr__(self, "s3", s3)
        object.__setattr__(self, "sigma", float(self.sigma))
        object.__setattr__(self, "rho", float(self.rho))
        if not self.label:
            text = f"{self.stage}: S2 {'+'.join(s2)}" + (f", S3 {'+'.join(s3)}" if s3 else "")
            object.__setattr__(self, "label", text)

    def replace(self, **changes: object) -> Adjustment:
        """A copy with some fields changed (the label is rebuilt when the link sets or stage change)."""
        new = dataclasses.replace(self, **changes)  # type: ignore[arg-type]
        if "label" not in changes and (new.s2, new.s3, new.stage) != (self.s2, self.s3, self.stage):
            new = dataclasses.replace(new, label="")
        return new

    def width(self, fps: float) -> float:
        """Kernel width in frames at ``fps``."""
        return self.sigma * float(fps)


#: The paper's ground schedule (section 4.1): lean with the lower body
#: (upper body keeps its orientation), then the upper body, then the arms.
GROUND_SCHEDULE: tuple[Adjustment, ...] = (
    Adjustment(("lower_body",), ("upper_body",), 40 / 30, 0.5, "ground", "ground: lower body (S2), upper body (S3)"),
    Adjustment(("upper_body",), (), 20 / 30, 0.3, "ground", "ground: upper body (S2)"),
    Adjustment(("arms",), (), 10 / 30, 0.2, "ground", "ground: arms (S2)"),
)

#: The paper's flight schedule (section 4.1): lower body, upper body, all.
FLIGHT_SCHEDULE: tuple[Adjustment, ...] = (
    Adjustment(("lower_body",), (), 10 / 30, 0.3, "flight", "flight: lower body (S2)"),
    Adjustment(("upper_body",), (), 10 / 30, 0.3, "flight", "flight: upper body (S2)"),
    Adjustment(("all",), (), 5 / 30, 1.0, "flight", "flight: whole body (S2)"),
)


def default_schedule(
    stage: Literal["ground", "flight", "both"] = "both", *, contacts: Contacts | None = None
) -> tuple[Adjustment, ...]:
    """The paper's default schedules.

    ``stage="both"`` gives the flight schedule followed by the ground one,
    so that every pass ends by balancing the ground frames, the take-off
    and landing windows that the flight adjustments moved included; with
    ``contacts`` given, the flight part is left out when the clip has no
    flight frame.

    Parameters
    ----------
    stage : {"both", "ground", "flight"}
        Which schedule.
    contacts : Contacts, optional
        With ``stage="both"``: the clip's contacts, to leave out the flight part when it never leaves the ground.

    Returns
    -------
    tuple of Adjustment

    Examples
    --------
    >>> import mocaplab as ml
    >>> [a.label for a in ml.physics.default_schedule("ground")]
    ['ground: lower body (S2), upper body (S3)', 'ground: upper body (S2)', 'ground: arms (S2)']
    >>> walk = ml.cmu("16_15").resample(30)[:60]
    >>> len(ml.physics.default_schedule()), len(ml.physics.default_schedule(contacts=ml.contacts.foot_contacts(walk)))
    (6, 3)
    """
    if stage == "ground":
        return GROUND_SCHEDULE
    if stage == "flight":
        return FLIGHT_SCHEDULE
    if stage != "both":
        raise ValueError(f"Expected `stage` 'ground', 'flight' or 'both', got {stage!r}")
    if contacts is not None and not flight_stages(contacts):
        return GROUND_SCHEDULE
    return FLIGHT_SCHEDULE + GROUND_SCHEDULE


_SCHEDULES = ("default", "ground", "flight", "both")


def check_schedule(schedule: Any) -> str | tuple[Adjustment, ...]:
    """``schedule`` checked before any work: a preset name, or its adjustments as a tuple.

    Parameters
    ----------
    schedule : "default", "ground", "flight", "both", Adjustment or sequence of Adjustment

    Raises
    ------
    TypeError
        Neither a name, an Adjustment nor a non-empty sequence of them (the
        message names the first item that is not an Adjustment).
    ValueError
        An unknown name.
    """
    expected = "'default', 'ground', 'flight', 'both', an Adjustment or a non-empty sequence of Adjustment"
    if isinstance(schedule, str):
        if schedule not in _SCHEDULES:
            raise ValueError(f"Expected `schedule` {expected}, got {schedule!r}")
        return schedule
    if isinstance(schedule, Adjustment):
        return (schedule,)
    if not isinstance(schedule, Sequence) or not schedule:
        raise TypeError(f"Expected `schedule` {expected}, got {type(schedule).__name__} {schedule!r:.80}")
    out = tuple(schedule)
    for k, a in enumerate(out):
        if not isinstance(a, Adjustment):
            raise TypeError(f"Expected `schedule[{k}]` to be an Adjustment, got {type(a).__name__} {a!r:.80}")
    return out


def _as_schedule(schedule: str | Adjustment | Sequence[Adjustment], contacts: Contacts) -> tuple[Adjustment, ...]:
    checked = check_schedule(schedule)
    if checked == "default":
        return default_schedule("both", contacts=contacts)
    if isinstance(checked, str):
        return default_schedule(checked, contacts=contacts if checked == "both" else None)  # type: ignore[arg-type]
    return checked


# ======================================================================
# link sets
# ======================================================================
PRESETS = ("lower_body", "upper_body", "arms", "all")


def _subtree(skeleton: Skeleton, j: int) -> NDArray[np.bool_]:
    mask = np.zeros(skeleton.n_joints, dtype=bool)
    mask[j] = True
    for k in range(j + 1, skeleton.n_joints):
        if mask[skeleton.parents[k]]:
            mask[k] = True
    return mask


def preset_mask(skeleton: Skeleton, name: str, *, roles: Mapping[str, Any] | None = None) -> NDArray[np.bool_]:
    """Joints of a preset (or of a joint's subtree), shape (J,) bool.

    Presets come from the joint roles (:mod:`mocaplab.roles`):
    ``"upper_body"`` is the subtree of the joint above the pelvis on the way
    to the neck (the first spine joint, or the neck when the spine role is
    empty: ``LowerBack`` on CMU, ``abdomen`` on Daz), ``"lower_body"``
    everything else (the root, the pelvis, the legs, and a static reference
    joint above the pelvis if there is one), ``"arms"`` the subtrees of
    both upper-arm joints (the ``shoulder`` roles), ``"all"`` every joint.
    Any other string must be a joint name: that joint and its descendants.

    Parameters
    ----------
    skeleton : Skeleton
    name : str
    roles : mapping of role names to joint names, optional
        Role overrides (:func:`mocaplab.roles.resolve_roles`).

    Returns
    -------
    ndarray of bool, shape (J,)

    Raises
    ------
    KeyError
        When ``name`` is neither a preset nor a joint of the skeleton (the message lists both).

    Examples
    --------
    >>> import mocaplab as ml
    >>> sk = ml.cmu("16_15").skeleton
    >>> [sk.names[j] for j, kept in enumerate(ml.physics.preset_mask(sk, "LeftLeg")) if kept]
    ['LeftLeg', 'LeftFoot', 'LeftToeBase']
    >>> int(ml.physics.preset_mask(sk, "arms").sum())
    12
    """
    if name == "all":
        return np.ones(skeleton.n_joints, dtype=bool)
    if name in ("upper_body", "lower_body"):
        r = resolve_roles(skeleton, roles)
        r.require("pelvis", "neck", purpose=f"the {name!r} preset")
        pelvis, neck = r.index("pelvis"), r.index("neck")
        try:
            chain = skeleton.chain(pelvis, neck)
        except ValueError:
            chain = []
        if len(chain) < 2:
            raise RolesError(
                f"The {name!r} preset needs the neck {r['neck']!r} below the pelvis {r['pelvis']!r}; "
                "give the roles with roles={'pelvis': ..., 'neck': ...} or name the joints"
            )
        upper = _subtree(skeleton, chain[1])
        return upper if name == "upper_body" else ~upper
    if name == "arms":
        r = resolve_roles(skeleton, roles)
        r.require("left_shoulder", "right_shoulder", purpose="the 'arms' preset")
        left, right = r.indices("left_shoulder", "right_shoulder")
        return _subtree(skeleton, left) | _subtree(skeleton, right)
    if name not in skeleton.names:
        raise KeyError(f"{name!r} is neither a preset {list(PRESETS)} nor a joint; joints are {list(skeleton.names)}")
    return _subtree(skeleton, skeleton.index(name))


@dataclasses.dataclass(frozen=True, eq=False)
class LinkSets:
    """The S1/S2/S3 split of a skeleton for one adjustment.

    Built by :func:`link_sets`.

    Parameters
    ----------
    roles : ndarray of int, shape (J,)
        1, 2 or 3 per joint.
    s2_tops : tuple of int
        Top joint of each connected part of S2.
    carried : tuple of (int, int)
        ``(joint, part)``: top joints of S3 (or S1) parts hanging below S2
        part ``part``; they are counter-rotated to keep their orientation.
    carried_s1 : tuple of bool
        Whether each carried top is an S1 part (only below a root-holding S2).
    part : ndarray of int, shape (J,)
        S2 part moving each joint (-1 for joints that do not move).
    carried_top : ndarray of int, shape (J,)
        For joints of a carried part, its top joint; -1 elsewhere.

    Examples
    --------
    >>> import numpy as np
    >>> import mocaplab as ml
    >>> sets = ml.physics.link_sets(ml.cmu("16_15").skeleton, ml.physics.Adjustment(("lower_body",), ("upper_body",)))
    >>> np.bincount(sets.roles, minlength=4)[1:].tolist()       # joints in S1, S2, S3
    [0, 11, 20]
    """

    roles: NDArray[np.int64]
    s2_tops: tuple[int, ...]
    carried: tuple[tuple[int, int], ...]
    carried_s1: tuple[bool, ...]
    part: NDArray[np.int64]
    carried_top: NDArray[np.int64]

    def names(self, skeleton: Skeleton, role: int) -> list[str]:
        """Joint names with the given role (1, 2 or 3)."""
        return [skeleton.names[j] for j in np.flatnonzero(self.roles == role)]


def link_sets(skeleton: Skeleton, adjustment: Adjustment, *, roles: Mapping[str, Any] | None = None) -> LinkSets:
    """Resolve an adjustment's S1/S2/S3 on a skeleton and check its shape.

    Results are cached per skeleton, roles and link sets.

    Parameters
    ----------
    skeleton : Skeleton
    adjustment : Adjustment
    roles : mapping, optional
        Joint-role overrides for the presets (see :func:`preset_mask`).

    Returns
    -------
    LinkSets

    Raises
    ------
    ValueError
        When S3 does not hang below S2, when S2 hangs below S3, or when an S1
        part hangs below an S2 part that does not hold the root.

    Examples
    --------
    >>> import mocaplab as ml
    >>> sk = ml.cmu("16_15").skeleton
    >>> sets = ml.physics.link_sets(sk, ml.physics.Adjustment(("arms",)))
    >>> [sk.names[j] for j in sets.s2_tops]
    ['LeftArm', 'RightArm']
    """
    r = resolve_roles(skeleton, roles)
    return _link_sets(skeleton, adjustment.s2, adjustment.s3, tuple(r.items()))


@lru_cache(maxsize=128)
def _link_sets(
    skeleton: Skeleton, s2: tuple[str, ...], s3: tuple[str, ...], role_items: tuple[tuple[str, Any], ...]
) -> LinkSets:
    n = skeleton.n_joints
    known = Roles(skeleton.names, dict(role_items))
    roles = np.ones(n, dtype=np.int64)
    for name in s2:
        roles[preset_mask(skeleton, name, roles=known)] = 2
    for name in s3:
        roles[preset_mask(skeleton, name, roles=known)] = 3
    if not np.any(roles == 2):
        raise ValueError(f"S2 ({'+'.join(s2)}) is empty on this skeleton (S3 covers it)")
    parents = skeleton.parents
    part = np.full(n, -1, dtype=np.int64)
    tops: list[int] = []
    carried: list[tuple[int, int]] = []
    carried_s1: list[bool] = []
    for j in range(n):
        p = int(parents[j])
        if roles[j] == 2:
            if p < 0 or roles[p] == 1:
                tops.append(j)
                part[j] = len(tops) - 1
            elif roles[p] == 3:
                raise ValueError(f"S2 joint {skeleton.names[j]!r} hangs below S3 joint {skeleton.names[p]!r}")
            else:
                part[j] = part[p]
        elif roles[j] == 3:
            if p < 0 or roles[p] == 1:
                where = "is the root" if p < 0 else f"hangs below S1 joint {skeleton.names[p]!r}"
                raise ValueError(f"S3 must hang below S2, but S3 joint {skeleton.names[j]!r} {where}")
            part[j] = part[p]
            if roles[p] == 2:
                carried.append((j, int(part[p])))
                carried_s1.append(False)
        else:
            if p >= 0 and part[p] >= 0:
                if roles[p] == 2 and tops[int(part[p])] == 0:
                    part[j] = part[p]
                    carried.append((j, int(part[p])))
                    carried_s1.append(True)
                elif roles[p] == 3:
                    raise ValueError(f"S1 joint {skeleton.names[j]!r} hangs below S3 joint {skeleton.names[p]!r}")
                else:
                    part[j] = part[p]
                    if roles[p] == 2:
                        raise ValueError(
                            f"S1 joint {skeleton.names[j]!r} hangs below S2 joint {skeleton.names[p]!r}, "
                            "which does not hold the root: it would move"
                        )
    carried_top = np.full(n, -1, dtype=np.int64)
    for u, _ in carried:
        carried_top[_subtree(skeleton, u)] = u
    # cached and handed out: read-only for good
    return LinkSets(readonly(roles), tuple(tops), tuple(carried), tuple(carried_s1), readonly(part), readonly(carried_top))


# ======================================================================
# stages
# ======================================================================
#: Shortest flight, seconds: a stretch without contact that is shorter is a
#: gap in the contact labels, not a flight (it gets neither ground nor
#: flight adjustments).  The flights of the shared clips last 75 ms or more
#: (runs 0.11-0.24 s on CMU 09_06, 16_35 and 127_04; the shortest, a dance's
#: 3 frames at 40 fps), while a fast walk's toe-off can be labelled 17-42 ms
#: before the other heel strike (the realworld file
#: pymo/AV_8Walk_Meredith_HVHA_Rep1, 120 fps).  Given flight adjustments,
#: those gaps made the touch-up of that walk, bent and refined, turn a knee
#: at up to 2.1x the input's angular acceleration (719 rad/s^2, 2 frames
#: before a gap); without them 0.95x.  A rule in frames (2) let 17 ms count
#: at 120 fps and nothing under 67 ms at 30 fps.
MIN_FLIGHT = 0.05


def flight_stages(
    contacts: Contacts, *, min_frames: int = 2, min_duration: float = MIN_FLIGHT, at_ends: bool = False
) -> list[tuple[int, int]]:
    """Half-open frame intervals with no joint planted (at least ``min_frames`` and ``min_duration`` long).

    With ``at_ends=False`` (default) a stretch without contact that touches
    the clip's first or last frame is left out: its take-off or its landing
    lies outside the clip, so there is no flight between known ends to fit
    a parabola to (a clip that starts or stops in the air, or a contact
    detection gap there).  The touch-up adjusts neither ground nor flight
    constraints on such frames.

    Parameters
    ----------
    contacts : Contacts
    min_frames : int, default 2
        Shortest flight, frames.
    min_duration : float, default :data:`MIN_FLIGHT`
        Shortest flight, seconds (the same at any frame rate).
    at_ends : bool, default False
        Keep stretches that touch the clip's first or last frame.

    Returns
    -------
    list of (int, int)
        ``(start, stop)`` frame intervals.

    Examples
    --------
    >>> import mocaplab as ml
    >>> walk = ml.cmu("16_15").resample(30)[:60]
    >>> ml.physics.flight_stages(ml.contacts.foot_contacts(walk))     # a walk never flies
    []
    """
    if not np.isfinite(min_duration) or min_duration < 0:
        raise ValueError(f"Expected `min_duration` >= 0 seconds, got {min_duration!r}")
    ground = np.asarray(contacts.mask, dtype=bool).any(axis=1)
    edges = np.diff(np.concatenate(([0], (~ground).astype(np.int8), [0])))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    n = ground.shape[0]
    shortest = max(min_frames, min_duration * contacts.fps - 1e-9)
    return [
        (int(a), int(b))
        for a, b in zip(starts, stops, strict=True)
        if b - a >= shortest and (at_ends or (a > 0 and b < n))
    ]
