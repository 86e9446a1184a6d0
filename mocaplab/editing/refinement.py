"""Full-body refinement after an edit (Kim et al. 2009, section 4.3).

After a path or timing edit the feet slide and the hands miss what they
should touch.  :func:`refine` builds goals from the foot contacts (detected
on the motion before editing when ``reference`` is given: its contacts are
right) and from end-effector constraints, and meets them with the shared
goal layer (:func:`mocaplab.goals.enforce_goals`: per-frame IK, a
hierarchical displacement map, a last exact IK pass).
:func:`refine_scene` does the same for several characters whose
constraints refer to each other (palms meeting in a high five): mutual
pairs meet halfway, other cross-character targets follow the refined
character they point at.

Measures: :func:`foot_skate` (mm per frame), :func:`end_effector_residuals`
(mm) and :func:`max_joint_angle_jump` (degrees).

Examples
--------
>>> import mocaplab as ml                                # doctest: +SKIP
>>> walk = ml.cmu("16_15")                               # doctest: +SKIP
>>> fixed = ml.refine(edited, reference=walk)            # doctest: +SKIP
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from .. import quat
from .._api import reject_keywords
from .._checks import real
from .._warnings import warn
from ..contacts import Contacts, estimate_floor, resolve_contacts
from ..goals import (
    EndEffector,
    Goal,
    RelativeTo,
    effector_goals,
    enforce_goals,
    foot_goals,
    map_options,
    world_targets,
)
from ..ik import UnreachableTargetWarning, unreachable_message
from ..motion import Motion

__all__ = [
    "refine",
    "refine_scene",
    "foot_skate",
    "end_effector_residuals",
    "max_joint_angle_jump",
]

Array = NDArray[np.float64]
JointRef = str | int


# ------------------------------------------------------------------ refine
#: Keywords of earlier versions, and what to write instead.
_RENAMED = MappingProxyType({
    "feet": "refine(..., feet=False) is refine(..., contacts=None) (plant no feet); feet=True is the default "
    "contacts='auto'",
})


def refine(
    motion: Motion,
    *,
    contacts: Contacts | Literal["auto"] | None = "auto",
    end_effectors: Sequence[EndEffector] = (),
    reference: Motion | None = None,
    blend: float = 0.1,
    spacing: float = 0.25,
    levels: int = 3,
    adjust_root: bool = True,
    dls_options: dict[str, Any] | None = None,
    roles: Mapping[str, Any] | None = None,
    **removed: Any,
) -> Motion:
    """Clean foot skate and enforce end-effector constraints (Kim et al. 2009 s4.3).

    Parameters
    ----------
    motion : Motion
        The edited motion.
    contacts : "auto", None or Contacts
        Foot contacts to plant (:func:`mocaplab.contacts.resolve_contacts`):
        ``"auto"`` detects them on ``reference`` when given (the motion
        before editing, whose contacts are right), else on ``motion``;
        ``None`` plants no feet (only end effectors).
    end_effectors : sequence of EndEffector
        Extra constraints (``character`` must be 0 and any
        :class:`RelativeTo` must refer to this character).
    reference : Motion, optional
        The motion before editing, with the same number of frames.  Where
        its contacts show an inclined floor
        (:func:`mocaplab.contacts.estimate_floor`), the body and its plants
        climb or descend with the floor wherever the edit moved them on the
        ground plane.
    blend : float
        Blending window on each side of every constraint, seconds (>= 0).
    spacing, levels : float, int
        Coarsest knot spacing (seconds, > 0) and number of levels of the
        displacement map (1 to :data:`mocaplab.goals.MAX_LEVELS`).
    adjust_root : bool
        Lower the root where a leg cannot reach its plant.
    dls_options : dict, optional
        Options of :func:`~mocaplab.ik.dls_ik` for end effectors with a chain.
    roles : mapping, optional
        Joint-role overrides for the default foot contacts
        (:func:`mocaplab.roles.resolve_roles`); the feet are the skeleton's
        ankle and toe roles.
    **removed
        Old keywords (``feet=``), answered with a ``TypeError`` that says
        what to write instead.

    Returns
    -------
    Motion
        A new motion; ``motion`` and ``reference`` are not modified.

    Warns
    -----
    UnreachableTargetWarning
        An end effector misses its target by more than 1 mm, or a planted
        foot joint misses its plant by more than :data:`PLANT_TOLERANCE`
        (50 mm) on frames its contact holds fully: the edit moved the body
        beyond the leg's reach of the plant, even with the root lowered by
        the most the goal layer allows (15 cm), and the foot slides.

    Examples
    --------
    A second of walk whose root drifts 30 cm sideways, so the planted feet
    skate; refining against the walk plants them again:

    >>> import numpy as np
    >>> import mocaplab as ml
    >>> from mocaplab.quality import skate
    >>> walk = ml.cmu("16_15")[:120]
    >>> drift = walk.replace(root_positions=walk.root_positions + np.outer(np.linspace(0, 0.3, 120), [1, 0, 0]))
    >>> clean = ml.refine(drift, reference=walk)
    >>> contacts = ml.contacts.foot_contacts(walk)
    >>> before, after = (float(np.nanmean(skate(m, contacts))) for m in (drift, clean))
    >>> round(before, 1), after < before / 3
    (3.1, True)
    """
    reject_keywords("refine", removed, _RENAMED, _ALLOWED + ("contacts", "end_effectors", "reference"))
    blend, spacing, levels = _checked(blend, spacing, levels)
    if not isinstance(motion, Motion):
        raise TypeError(f"Expected `motion` to be a Motion, got {type(motion).__name__}")
    if reference is not None and not isinstance(reference, Motion):
        raise TypeError(f"Expected `reference` to be a Motion or None, got {type(reference).__name__}")
    for ee in end_effectors:
        if not isinstance(ee, EndEffector):
            raise TypeError(f"Expected EndEffector objects in `end_effectors`, got {type(ee).__name__}")
        if ee.character != 0 or (isinstance(ee.target, RelativeTo) and ee.target.character not in (None, 0)):
            raise ValueError("refine() takes one character; use refine_scene() for constraints between characters")
    for k, ee in enumerate(end_effectors):
        ee.check(motion, label=f"end_effectors[{k}] ({ee.joint!r}, frames={ee.frames!r})")
    targets = [world_targets(ee, [motion]) for ee in end_effectors]
    return _refine_one(
        motion, end_effectors, targets, contacts=contacts, reference=reference, blend=blend,
        spacing=spacing, levels=levels, adjust_root=adjust_root, dls_options=dls_options, roles=roles,
    )


def _refine_one(
    motion: Motion,
    end_effectors: Sequence[EndEffector],
    targets: Sequence[Array],
    *,
    contacts: Contacts | Literal["auto"] | None,
    reference: Motion | None,
    blend: float,
    spacing: float,
    levels: int,
    adjust_root: bool,
    dls_options: dict[str, Any] | None,
    roles: Mapping[str, Any] | None = None,
    label: str = "",
) -> Motion:
    goals: list[Goal] = []
    c = resolve_contacts(contacts, reference if reference is not None else motion, roles=roles)
    if c is not None:
        if reference is not None:
            motion = _on_floor(motion, reference, c)
        goals += foot_goals(motion, c, reference=reference, blend=blend)
    goals += effector_goals(motion, end_effectors, targets, blend=blend)
    out = enforce_goals(
        motion, goals, spacing=spacing, levels=levels, adjust_root=adjust_root, dls_options=dls_options
    )
    _warn_missed(out, end_effectors, targets)
    _warn_lost_plants(out, [g for g in goals if g.kind in ("foot", "toe")], label)
    return out


#: A planted foot joint further than this (metres) from its plant on a frame its goal holds fully is reported
#: (:func:`refine`).  Refinement meets plants to a few millimetres, and up to about 26 mm where an ankle's and a
#: toe's plants disagree with the foot's length (the shared files and CMU clips, edited or not); an edit that
#: moves the body out of a leg's reach of its plant misses it by decimetres or metres.
PLANT_TOLERANCE = 0.05


def _warn_lost_plants(motion: Motion, goals: Sequence[Goal], label: str = "") -> None:
    """One warning per foot joint that misses its plant by more than :data:`PLANT_TOLERANCE` where held fully."""
    if not goals:
        return
    pos = motion.global_positions()
    for g in goals:
        held = g.weights >= 1.0 - 1e-9
        j = motion.skeleton.index(g.joint)
        miss = np.zeros(motion.n_frames)
        miss[held] = np.linalg.norm(pos[held, j] - g.targets[held], axis=-1)
        message = unreachable_message(motion.skeleton.names[j], miss, tolerance=PLANT_TOLERANCE)
        if message is not None:
            warn(
                f"{label}foot plant {message}: the body is beyond the leg's reach of where the foot was planted, "
                "even with the root lowered, and the foot slides (an edit that moves the path far from a planted "
                "foot does this: keep the path's pins nearer the captured path there)",
                UnreachableTargetWarning,
            )


def _on_floor(motion: Motion, reference: Motion, contacts: Contacts) -> Motion:
    """``motion`` raised or lowered with the floor under its path joint, where the edit moved it.

    Path editing moves the body on the ground plane only; on a floor inclined
    as the reference's contacts say (:func:`mocaplab.contacts.estimate_floor`:
    level within 2 degrees) the
    body must climb or descend with it, by ``slope . (p' - p)`` for the path
    joint's ground positions ``p'`` (edited) and ``p`` (reference).  The foot
    goals put the plants on the floor there too
    (:func:`mocaplab.goals.foot_goals`).  ``motion`` is ``reference`` moved
    on the ground plane (a path edit): a motion already lifted would be
    lifted again.
    """
    floor = estimate_floor(reference, contacts)
    if floor is None or not floor.slope.any():
        return motion
    lift = (motion.pelvis_positions - reference.pelvis_positions)[:, [0, 2]] @ floor.slope
    if not np.any(np.abs(lift) > 1e-9):
        return motion
    return motion.transformed(translation=np.stack([np.zeros_like(lift), lift, np.zeros_like(lift)], axis=-1))


def _warn_missed(motion: Motion, end_effectors: Sequence[EndEffector], targets: Sequence[Array]) -> None:
    """One warning per end effector that misses its target by more than 1 mm on constrained frames."""
    if not end_effectors:
        return
    pos = motion.global_positions()
    for ee, tgt in zip(end_effectors, targets, strict=True):
        frames = np.concatenate([np.arange(a, b) for a, b in ee.intervals(motion.n_frames)])
        miss = np.zeros(motion.n_frames)
        miss[frames] = np.linalg.norm(pos[frames, motion.skeleton.index(ee.joint)] - np.asarray(tgt)[frames], axis=-1)
        message = unreachable_message(ee.joint, miss)
        if message is not None:
            warn(f"end effector {message}", UnreachableTargetWarning)


def _mutual_pairs(end_effectors: Sequence[EndEffector]) -> list[tuple[int, int]]:
    pairs = []
    for a, ea in enumerate(end_effectors):
        ta = ea.target
        if not isinstance(ta, RelativeTo) or ta.character is None or ta.character == ea.character:
            continue
        for b in range(a + 1, len(end_effectors)):
            eb = end_effectors[b]
            tb = eb.target
            if (
                isinstance(tb, RelativeTo)
                and eb.character == ta.character
                and tb.character == ea.character
                and tb.joint == ea.joint
                and ta.joint == eb.joint
            ):
                pairs.append((a, b))
    return pairs


def refine_scene(
    motions: Sequence[Motion],
    end_effectors: Sequence[EndEffector] = (),
    *,
    contacts: Sequence[Contacts | Literal["auto"] | None] | Literal["auto"] | None = "auto",
    references: Sequence[Motion | None] | None = None,
    **options: Any,
) -> list[Motion]:
    """Refine several characters whose end effectors may refer to each other.

    Parameters
    ----------
    motions : sequence of Motion
        The characters (equal frame counts where constraints relate them).
    end_effectors : sequence of EndEffector
        ``character`` says whose joint is constrained; a :class:`RelativeTo`
        target with ``character=k`` follows character ``k``'s joint.
    contacts : "auto", None, or a sequence of them and Contacts
        As in :func:`refine`: one value for every character, or one per
        character.
    references : sequence of Motion or None, optional
        Per character, as in :func:`refine`.
    **options
        Passed to :func:`refine` (``blend``, ``spacing``, ``levels``,
        ``feet``, ``adjust_root``, ``dls_options``).

    Returns
    -------
    list of Motion

    Notes
    -----
    Mutual pairs (A's joint relative to B's and B's relative to A's) meet at
    the midpoint of the two joints before refinement, plus half the agreed
    offset ``(offset_A - offset_B) / 2`` each way.  Other relative targets
    are resolved against the *refined* other character, so characters are
    refined in dependency order; a longer cycle raises ValueError.
    """
    opts = _options(options)  # checked before any work
    motions = list(motions)
    if not motions or not all(isinstance(m, Motion) for m in motions):
        raise TypeError("Expected `motions` to be a non-empty sequence of Motion")
    n_chars = len(motions)
    if contacts is None or isinstance(contacts, str):
        contacts = [contacts] * n_chars
    for name, seq in (("contacts", contacts), ("references", references)):
        if seq is not None and len(seq) != n_chars:
            raise ValueError(f"Expected `{name}` with one entry per character ({n_chars}), got {len(seq)}")
    ees = list(end_effectors)
    for k, ee in enumerate(ees):
        if not isinstance(ee, EndEffector):
            raise TypeError(f"Expected EndEffector objects in `end_effectors`, got {type(ee).__name__}")
        if not 0 <= ee.character < n_chars:
            raise ValueError(f"Expected EndEffector character in [0, {n_chars}), got {ee.character}")
        ee.check(motions[ee.character], label=f"end_effectors[{k}] ({ee.joint!r}, frames={ee.frames!r})")
        t = ee.target
        if isinstance(t, RelativeTo) and t.character is not None and not 0 <= t.character < n_chars:
            raise ValueError(f"Expected RelativeTo character in [0, {n_chars}), got {t.character}")
    mutual: dict[int, Array] = {}
    for a, b in _mutual_pairs(ees):
        ea, eb = ees[a], ees[b]
        ma, mb = motions[ea.character], motions[eb.character]
        if ma.n_frames != mb.n_frames:
            raise ValueError(f"Expected characters with equal frame counts, got {ma.n_frames} and {mb.n_frames}")
        pa = ma.global_positions()[:, ma.skeleton.index(ea.joint)]
        pb = mb.global_positions()[:, mb.skeleton.index(eb.joint)]
        ta, tb = ea.target, eb.target
        if not (isinstance(ta, RelativeTo) and isinstance(tb, RelativeTo)):  # pragma: no cover (by _mutual_pairs)
            raise TypeError("mutual end effectors must both target RelativeTo")
        gap = 0.5 * (np.asarray(ta.offset) - np.asarray(tb.offset))
        mid = 0.5 * (pa + pb)
        mutual[a] = mid + 0.5 * gap
        mutual[b] = mid - 0.5 * gap
    # dependency order for the remaining cross-character targets
    deps: dict[int, set[int]] = {c: set() for c in range(n_chars)}
    for k, ee in enumerate(ees):
        t = ee.target
        if k not in mutual and isinstance(t, RelativeTo) and t.character not in (None, ee.character):
            deps[ee.character].add(int(t.character))  # type: ignore[arg-type]
    order: list[int] = []
    pending = set(range(n_chars))
    while pending:
        ready = sorted(c for c in pending if deps[c] <= set(order))
        if not ready:
            raise ValueError(f"End-effector constraints form a cycle between characters {sorted(pending)}")
        order += ready
        pending -= set(ready)
    current = list(motions)
    for c in order:
        mine = [k for k, ee in enumerate(ees) if ee.character == c]
        tg = []
        for k in mine:
            # current[c] is still the unrefined motion here
            tg.append(mutual[k] if k in mutual else world_targets(ees[k], current))
        current[c] = _refine_one(
            motions[c], [ees[k] for k in mine], tg,
            contacts=contacts[c],
            reference=None if references is None else references[c],
            label=f"character {c}: " if n_chars > 1 else "",
            **opts,
        )
    return current


_ALLOWED = ("blend", "spacing", "levels", "adjust_root", "dls_options", "roles")


def _options(options: dict[str, Any]) -> dict[str, Any]:
    reject_keywords("refine_scene", {k: v for k, v in options.items() if k not in _ALLOWED}, _RENAMED, _ALLOWED)
    defaults: dict[str, Any] = {
        "blend": 0.1, "spacing": 0.25, "levels": 3, "adjust_root": True, "dls_options": None, "roles": None,
    }
    defaults.update(options)
    defaults["blend"], defaults["spacing"], defaults["levels"] = _checked(
        defaults["blend"], defaults["spacing"], defaults["levels"]
    )
    return defaults


def _checked(blend: Any, spacing: Any, levels: Any) -> tuple[float, float, int]:
    """refine's numeric options, checked before any contact is detected (TypeError/ValueError naming the option)."""
    return (real(blend, "blend", low=0.0, unit="seconds"), *map_options(spacing, levels))


# ----------------------------------------------------------------- measures
def foot_skate(motion: Motion, contacts: Contacts) -> Array:
    """Horizontal slide of planted joints, millimetres per frame, shape (F,).

    Entry ``i`` is the largest ground-plane distance ``|p(i+1) - p(i)|``
    (x and z only) over the contact joints planted on both frames ``i`` and
    ``i + 1``; NaN where no joint is planted on both (so
    ``np.nanmean(foot_skate(m, c))`` is the mean skate per planted frame):
    :meth:`mocaplab.contacts.Contacts.slide` (as :func:`mocaplab.quality.skate`)
    with a NaN for the last frame, so that it lines up with the motion's frames.
    """
    if not isinstance(motion, Motion):
        raise TypeError(f"Expected `motion` to be a Motion, got {type(motion).__name__}")
    if not isinstance(contacts, Contacts):
        raise TypeError(f"Expected `contacts` to be a Contacts, got {type(contacts).__name__}")
    return np.append(contacts.slide(motion), np.nan)


def end_effector_residuals(
    motions: Motion | Sequence[Motion], end_effectors: Sequence[EndEffector]
) -> list[Array]:
    """Distance from each end effector to its target on its constrained frames, mm.

    Parameters
    ----------
    motions : Motion or sequence of Motion
        One motion, or the scene of :func:`refine_scene`.
    end_effectors : sequence of EndEffector

    Returns
    -------
    list of ndarray
        One array per end effector, shape (n_constrained_frames,).  Relative
        targets are measured against the given scene (mutual pairs: the
        distance between ``p_A`` and ``p_B + offset_A``).
    """
    scene = [motions] if isinstance(motions, Motion) else list(motions)
    out = []
    for k, ee in enumerate(end_effectors):
        if not isinstance(ee, EndEffector):
            raise TypeError(f"Expected EndEffector objects in `end_effectors`, got {type(ee).__name__}")
        if not 0 <= ee.character < len(scene):
            raise ValueError(f"EndEffector {k} names character {ee.character}, but the scene has {len(scene)}")
        m = scene[ee.character]
        tgt = world_targets(ee, scene)
        pos = m.global_positions()[:, m.skeleton.index(ee.joint)]
        frames = np.concatenate([np.arange(a, b) for a, b in ee.intervals(m.n_frames)])
        out.append(np.linalg.norm(pos[frames] - tgt[frames], axis=-1) * 1000.0)
    return out


def max_joint_angle_jump(before: Motion, after: Motion, *, joints: Sequence[JointRef] | None = None) -> float:
    """Largest per-frame change of the refinement's rotation correction, degrees.

    With the correction ``c_j(i) = q_before_j(i)^-1 q_after_j(i)`` of each
    joint (root orientation included), this is
    ``max_{i, j} angle(c_j(i)^-1 c_j(i+1))``: how much the refinement changes
    a joint angle between consecutive frames beyond what the original motion
    did.  Zero when ``after`` equals ``before`` or differs by a constant.
    """
    if before.rotations.shape != after.rotations.shape:
        raise ValueError(
            f"Expected motions of equal shape, got {before.rotations.shape} and {after.rotations.shape}"
        )
    if before.n_frames < 2:
        return 0.0
    sel = slice(None) if joints is None else [before.skeleton.index(j, arg="joints") for j in joints]
    c = quat.mul(quat.inv(before.rotations[:, sel]), after.rotations[:, sel])
    step = quat.mul(quat.inv(c[:-1]), c[1:])
    return float(np.degrees(quat.angle(step).max()))
