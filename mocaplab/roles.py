"""Joint roles: which joint of a skeleton is the pelvis, a knee, a wrist.

Every algorithm in mocaplab asks a skeleton's roles instead of a joint name,
so one implementation serves CMU, Mixamo, game-studio, Biped, Daz, SMPL and
hand-made skeletons alike.  :attr:`mocaplab.motion.Skeleton.roles` infers
them once and caches them; :meth:`~mocaplab.motion.Skeleton.with_roles`
overrides any of them.

Roles
-----
``pelvis``
    The joint both legs and the spine branch from; the joint whose ground
    projection is the motion path (it need not be joint 0: a static
    reference joint above a travelling pelvis is a common export layout).
``spine``
    The joints strictly between ``pelvis`` and ``neck``, pelvis side first
    (a tuple of any length, possibly empty).
``neck``, ``head``
    The first joint of the neck and the head joint.
``left_*``, ``right_*`` for ``hip``, ``knee``, ``ankle``, ``toe``, ``clavicle``, ``shoulder``, ``elbow``, ``wrist``
    ``hip``/``knee``/``ankle`` are the three joints of the two-bone leg
    (thigh from hip to knee, shank from knee to ankle); ``toe`` is the ball
    of the foot; ``shoulder``/``elbow``/``wrist`` are the two-bone arm and
    ``clavicle`` the joint between the spine and the shoulder.

On the CMU BVH skeleton: ``pelvis`` Hips, ``spine`` (LowerBack, Spine,
Spine1), ``neck`` Neck, ``head`` Head, ``left_hip`` LeftUpLeg, ``left_knee``
LeftLeg, ``left_ankle`` LeftFoot, ``left_toe`` LeftToeBase,
``left_clavicle`` LeftShoulder, ``left_shoulder`` LeftArm, ``left_elbow``
LeftForeArm, ``left_wrist`` LeftHand.  Roles a skeleton lacks (no toe, no
clavicle, no arms) are simply absent; what needs them says so.

How roles are inferred
----------------------
1. **Names.**  Each joint name is split into words (a ``prefix:``
   namespace and a ``Bip01``/``Bip001`` prefix are dropped; words break at
   spaces, ``_``, ``.``, ``-`` and camel case), a side word is taken off
   (``Left``/``Right``, ``L``/``R``, ``l``/``r``, also glued to a known word
   as in ``lfemur`` or ``leftfoot``) and the rest, lower-cased and joined,
   is looked up in :data:`NAMING`, the one table of naming conventions in
   the package.  Trailing digits are ignored when the exact word is not in
   the table (``Toe0``, ``Spine_01``).
2. **Topology.**  Names anchor the ankles and wrists; the limb joints above
   them come from the hierarchy: the knee is the nearest ancestor of the
   ankle that is named like a knee, else the nearest ancestor not at the
   ankle's own place (zero-length helper joints are skipped); likewise the
   hip above the knee, the elbow and shoulder above the wrist.  The toe is
   the descendant of the ankle named like a toe, else the ankle's only
   child.  The clavicle is the joint between the shoulder and the spine.
   ``pelvis`` is the lowest common ancestor of the two hips, ``neck`` the
   neck-named joint nearest the pelvis on the way to the head (else the
   joint just above the arms' branch), ``spine`` what lies between.
   When names give no ankles (or no wrists), the legs are the two chains
   below a common joint that reach lowest (the arms: the two side chains
   that branch from the upper spine), and the limb's joints are the ends of
   its two longest consecutive bones.
3. **Geometry.**  In a plausible pose (the rest pose, or frames of a
   motion given to :func:`infer_roles`: head well above the pelvis) the
   legs must reach below the pelvis and left and right are decided by the
   body's facing direction (the toes point forward; left is up x forward
   in the project's right-handed, Y-up frame).  Where named sides disagree
   with the facing direction, the sides are swapped with a warning; a
   degenerate rest pose (bones laid along one axis, rest rotations baked
   into the motion) is not used for checks.

When roles cannot be inferred, :class:`RolesError` lists what was found,
what is missing and the :meth:`~mocaplab.motion.Skeleton.with_roles` call
that fixes it.

Examples
--------
>>> from mocaplab.motion import Skeleton
>>> sk = Skeleton(
...     ["Hips", "UpperLeg_L", "LowerLeg_L", "Foot_L", "UpperLeg_R", "LowerLeg_R", "Foot_R", "Spine", "Neck", "Head"],
...     [-1, 0, 1, 2, 0, 4, 5, 0, 7, 8],
...     [[0, 1, 0], [0.1, 0, 0], [0, -0.45, 0], [0, -0.45, 0], [-0.1, 0, 0], [0, -0.45, 0], [0, -0.45, 0],
...      [0, 0.2, 0], [0, 0.3, 0], [0, 0.1, 0]],
... )
>>> sk.roles["left_knee"], sk.roles["pelvis"], sk.roles["spine"]
('LowerLeg_L', 'Hips', ('Spine',))
>>> "left_toe" in sk.roles
False

Longer than 800 lines because the naming table and the topology rules are one inference: names propose, the tree checks and completes, and the mirror map reuses both.
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Mapping, Sequence
from typing import Any, Literal, Protocol

import numpy as np
from numpy.typing import NDArray

from ._warnings import warn

__all__ = [
    "ROLE_NAMES",
    "LIMB_PARTS",
    "SIDES",
    "NAMING",
    "Roles",
    "RolesError",
    "infer_roles",
    "resolve_roles",
    "parse_name",
    "mirror_name",
    "mirror_map",
]


class Skeleton(Protocol):
    """What role inference reads of a skeleton (:class:`mocaplab.motion.Skeleton` is one).

    A structural type, so this module needs nothing from :mod:`mocaplab.motion`:
    the dependency runs one way, ``motion -> roles`` (a skeleton caches its
    roles; roles never import the skeleton class).
    """

    @property
    def names(self) -> tuple[str, ...]: ...

    @property
    def parents(self) -> NDArray[np.int64]: ...

    @property
    def offsets(self) -> NDArray[np.float64]: ...

    @property
    def n_joints(self) -> int: ...

    @property
    def roles(self) -> Roles: ...

    def with_roles(self, **roles: Any) -> Skeleton: ...

SIDES = ("left", "right")
LEG_PARTS = ("hip", "knee", "ankle", "toe")
ARM_PARTS = ("clavicle", "shoulder", "elbow", "wrist")
LIMB_PARTS = LEG_PARTS + ARM_PARTS
#: Every role name, in a fixed order.
ROLE_NAMES: tuple[str, ...] = ("pelvis", "spine", "neck", "head") + tuple(
    f"{s}_{p}" for s in SIDES for p in LIMB_PARTS
)

#: The naming conventions, written once: for each kind of joint, the words
#: (lower case, separators removed, side taken off) that name it, strongest
#: first.  CMU BVH (LeftUpLeg, LeftLeg, LeftFoot, LeftToeBase, LeftShoulder,
#: LeftArm, LeftForeArm, LeftHand, Hips, LowerBack, Spine, Spine1, Neck,
#: Head), CMU ASF (lfemur, ltibia, lfoot, ltoes, lclavicle, lhumerus,
#: lradius, lwrist, root, lowerback, upperback, thorax, lowerneck, head),
#: Mixamo (``mixamorig:`` + the BVH names, Spine2), game studios
#: (UpperLeg_L, LowerLeg_L, Foot_L, Toes_L, Clavicle_L, UpperArm_L,
#: LowerArm_L, Hand_L), 3ds Max Biped (Bip01 Pelvis, Bip01 L Thigh, L Calf,
#: L Foot, L Toe0, L Clavicle, L UpperArm, L Forearm, L Hand), Daz (hip,
#: abdomen, chest, lThigh, lShin, lFoot, lCollar, lShldr, lForeArm, lHand),
#: SMPL (pelvis, left_hip, left_knee, left_ankle, left_foot, spine1,
#: left_collar, left_shoulder, left_elbow, left_wrist) and LaFAN1
#: (LeftToe).  Ambiguous words ("shoulder" is a clavicle for CMU and an
#: upper arm for SMPL; "hip" is the pelvis for Daz and a thigh for SMPL)
#: are settled by the hierarchy.
NAMING: Mapping[str, tuple[str, ...]] = {
    "pelvis": ("hips", "pelvis", "hip", "root"),
    "spine": ("spine", "lowerback", "upperback", "abdomen", "chest", "upperchest", "thorax", "torso", "waist", "back"),
    "neck": ("neck", "lowerneck", "upperneck"),
    "head": ("head", "skull"),
    "hip": ("upleg", "upperleg", "thigh", "femur", "hip"),
    "knee": ("leg", "lowerleg", "shin", "calf", "knee", "tibia", "shank"),
    "ankle": ("ankle", "foot"),
    "toe": ("toebase", "toe", "toes", "ball", "foot"),
    "clavicle": ("clavicle", "collar", "clav", "scapula", "shoulder"),
    "shoulder": ("upperarm", "arm", "humerus", "shldr", "uparm", "shoulder"),
    "elbow": ("forearm", "lowerarm", "elbow", "radius", "ulna"),
    "wrist": ("wrist", "hand"),
}

# Other words joints are called by: they carry no role, but let a glued side
# letter be recognised (``lhipjoint``, ``lthumb``) and keep ``lowerback`` whole.
_OTHER_WORDS = frozenset(
    "hipjoint buttock fingers finger fingerbase handindex thumb index middle ring pinky mid eye toeend "
    "heel handthumb footend".split()
)
_KNOWN_WORDS = frozenset(w for words in NAMING.values() for w in words) | _OTHER_WORDS

_LEFT_WORDS = frozenset(("left", "l", "lf", "lft"))
_RIGHT_WORDS = frozenset(("right", "r", "rt", "rgt"))
_WORD_RE = re.compile(r"[A-Z]+(?=[A-Z][a-z])|[A-Z]?[a-z]+|[A-Z]+|\d+")
_BIPED_RE = re.compile(r"^bip0*1\b", re.IGNORECASE)


class RolesError(ValueError):
    """Joint roles could not be inferred (or an override does not fit).

    A ``ValueError``; its message names the missing roles and the call that
    supplies them.

    Examples
    --------
    >>> from mocaplab import Skeleton
    >>> sk = Skeleton(["hips", "knee"], [-1, 0], [[0, 0, 0], [0, -0.5, 0]])
    >>> sk.roles["left_knee"]
    Traceback (most recent call last):
    ...
    mocaplab.roles.RolesError: Could not infer the joint role(s) ['left_knee']. ...
    """


class RolesWarning(UserWarning):
    """Roles were inferred with a correction worth knowing about."""


# --------------------------------------------------------------------- names
def _words(name: str) -> list[tuple[str, int, int]]:
    """Words of a joint name with their spans: ``(word, start, stop)``."""
    start = name.rfind(":") + 1  # a namespace prefix (mixamorig:)
    body = name[start:]
    m = _BIPED_RE.match(body)
    if m:
        start += m.end()
    return [(w.group(0), w.start(), w.end()) for w in _WORD_RE.finditer(name, start)]


def parse_name(name: str) -> tuple[Literal["left", "right"] | None, str]:
    """The side and the base word of a joint name.

    Parameters
    ----------
    name : str
        A joint name in any of the common spellings (a namespace prefix such
        as ``mixamorig:`` and a ``Bip01`` prefix are ignored).

    Returns
    -------
    side : {"left", "right"} or None
        None when the name carries no side.
    base : str
        The rest of the name, lower case, without separators.

    Examples
    --------
    >>> parse_name("mixamorig:LeftUpLeg"), parse_name("UpperLeg_L"), parse_name("lfemur")
    (('left', 'upleg'), ('left', 'upperleg'), ('left', 'femur'))
    >>> parse_name("Bip01 R Calf"), parse_name("lowerback"), parse_name("Spine1")
    (('right', 'calf'), (None, 'lowerback'), (None, 'spine1'))
    """
    side, base, _ = _parse(name)
    return side, base


def _parse(name: str) -> tuple[Literal["left", "right"] | None, str, tuple[int, int, str] | None]:
    """Side, base word and the side's span and spelling in ``name`` (if any)."""
    words = _words(name)
    if not words:
        return None, "", None
    lower = [w.lower() for w, _, _ in words]
    for pos in (0, len(words) - 1):
        if lower[pos] in _LEFT_WORDS or lower[pos] in _RIGHT_WORDS:
            if len(words) == 1:
                break
            side: Literal["left", "right"] = "left" if lower[pos] in _LEFT_WORDS else "right"
            return side, "".join(lower[:pos] + lower[pos + 1 :]), (words[pos][1], words[pos][2], words[pos][0])
    joined = "".join(lower)
    # a side glued to a known word: lfemur, rtibia, leftfoot, footleft
    for word, s in (("left", "left"), ("right", "right"), ("l", "left"), ("r", "right")):
        w0, a0, _ = words[0]
        if lower[0].startswith(word) and len(lower[0]) > len(word):
            rest = lower[0][len(word) :] + "".join(lower[1:])
            if _known(rest) or _known(lower[0][len(word) :]):
                return s, rest, (a0, a0 + len(word), w0[: len(word)])  # type: ignore[return-value]
    for word, s in (("left", "left"), ("right", "right")):
        wl, _, bl = words[-1]
        if lower[-1].endswith(word) and len(lower[-1]) > len(word) and _known(joined[: -len(word)]):
            return s, joined[: -len(word)], (bl - len(word), bl, wl[-len(word) :])  # type: ignore[return-value]
    return None, joined, None


def _known(word: str) -> bool:
    return word in _KNOWN_WORDS or word.rstrip("0123456789") in _KNOWN_WORDS


def _kinds(base: str) -> dict[str, int]:
    """Kinds a base word names, with its rank in each kind's list (0 strongest)."""
    out = {}
    for b in (base, base.rstrip("0123456789")):
        for kind, words in NAMING.items():
            if b in words and kind not in out:
                out[kind] = words.index(b) + (0 if b == base else 100)
    return out


def mirror_name(name: str) -> str:
    """The name of the joint on the other side (the same name if it has no side).

    The side word keeps its spelling and case (``L`` becomes ``R``,
    ``Left`` becomes ``Right``).

    Parameters
    ----------
    name : str

    Returns
    -------
    str

    Examples
    --------
    >>> mirror_name("LeftArm"), mirror_name("Toes_L"), mirror_name("lfemur"), mirror_name("Bip01 L Thigh")
    ('RightArm', 'Toes_R', 'rfemur', 'Bip01 R Thigh')
    >>> mirror_name("lowerback"), mirror_name("mixamorig:RightHand")
    ('lowerback', 'mixamorig:LeftHand')
    """
    side, _, span = _parse(name)
    if side is None or span is None:
        return name
    a, b, spelled = span
    low = spelled.lower()
    other = {"left": "right", "l": "r", "lf": "rt", "lft": "rgt", "right": "left", "r": "l", "rt": "lf", "rgt": "lft"}[low]
    if spelled.isupper():
        other = other.upper()
    elif spelled[:1].isupper():
        other = other.capitalize()
    return name[:a] + other + name[b:]


# ----------------------------------------------------------------- the type
class Roles(Mapping[str, Any]):
    """An immutable mapping from role names to joint names.

    Values are joint names (``str``), except ``spine``, a tuple of names.
    Missing roles are absent (``"left_toe" in roles`` is False); indexing a
    missing role raises :class:`RolesError` saying how to supply it.

    Parameters
    ----------
    joint_names : tuple of str
        The skeleton's joint names (for :meth:`index`).
    mapping : mapping of str to str or tuple of str
        Role name (one of ``ROLE_NAMES``) to joint name; ``spine`` to a
        tuple of joint names, pelvis side first.  None values are dropped.
    notes : tuple of str, default ()
        What inference corrected or guessed, for the user to read.

    Raises
    ------
    RolesError
        For an unknown role name or a joint the skeleton does not have.

    Examples
    --------
    >>> roles = Roles(("hips", "LKnee"), {"pelvis": "hips", "left_knee": "LKnee"})
    >>> roles["left_knee"], roles.index("left_knee"), "right_knee" in roles
    ('LKnee', 1, False)
    """

    __slots__ = ("_names", "_map", "notes")

    def __init__(self, joint_names: tuple[str, ...], mapping: Mapping[str, Any], notes: tuple[str, ...] = ()):
        unknown = sorted(set(mapping) - set(ROLE_NAMES))
        if unknown:
            raise RolesError(f"Unknown role names {unknown}; roles are {list(ROLE_NAMES)}")
        ordered: dict[str, Any] = {}
        for role in ROLE_NAMES:
            if role in mapping and mapping[role] is not None:
                value = mapping[role]
                value = tuple(str(v) for v in value) if role == "spine" else str(value)
                for v in value if role == "spine" else (value,):
                    if v not in joint_names:
                        raise RolesError(f"Role {role!r} names joint {v!r}, which the skeleton does not have")
                ordered[role] = value
        self._names = tuple(joint_names)
        self._map = ordered
        self.notes = tuple(notes)

    def __getitem__(self, role: str) -> Any:
        try:
            return self._map[role]
        except KeyError:
            pass
        if role not in ROLE_NAMES:
            raise KeyError(f"{role!r} is not a role; roles are {list(ROLE_NAMES)}")
        raise RolesError(_missing_message(self, [role]))

    def __contains__(self, role: object) -> bool:
        return role in self._map

    def get(self, role: str, default: Any = None) -> Any:
        return self._map.get(role, default)

    def __iter__(self) -> Iterator[str]:
        return iter(self._map)

    def __len__(self) -> int:
        return len(self._map)

    def __repr__(self) -> str:
        body = ", ".join(f"{k}={v!r}" for k, v in self._map.items())
        return f"Roles({body})"

    def index(self, role: str) -> int:
        """Joint index of a single-joint role."""
        value = self[role]
        if role == "spine":
            raise ValueError("'spine' is a chain of joints; use spine_indices()")
        return self._names.index(value)

    def indices(self, *roles: str) -> list[int]:
        """Joint indices of the given roles that the skeleton has (missing ones skipped)."""
        return [self._names.index(self._map[r]) for r in roles if r in self._map and r != "spine"]

    def spine_indices(self) -> list[int]:
        """Joint indices of ``spine`` (pelvis side first)."""
        return [self._names.index(n) for n in self._map.get("spine", ())]

    def require(self, *roles: str, purpose: str = "") -> None:
        """Raise :class:`RolesError` naming the roles among ``roles`` that are missing."""
        missing = [r for r in roles if r not in self._map]
        if missing:
            raise RolesError(_missing_message(self, missing, purpose))

    def feet(self) -> list[tuple[str, str | None]]:
        """``(ankle, toe or None)`` for the left then the right foot (sides with an ankle)."""
        return [
            (self._map[f"{s}_ankle"], self._map.get(f"{s}_toe")) for s in SIDES if f"{s}_ankle" in self._map
        ]

    def foot_joints(self) -> tuple[str, ...]:
        """Ankle and toe joints of both feet: left ankle, left toe, right ankle, right toe."""
        self.require("left_ankle", "right_ankle", purpose="foot contacts")
        return tuple(j for ankle, toe in self.feet() for j in (ankle, toe) if j is not None)

    def limb(self, side: str, limb: Literal["leg", "arm"]) -> tuple[str, str, str]:
        """The two-bone limb ``(hip, knee, ankle)`` or ``(shoulder, elbow, wrist)`` of a side."""
        parts = ("hip", "knee", "ankle") if limb == "leg" else ("shoulder", "elbow", "wrist")
        names = [f"{side}_{p}" for p in parts]
        self.require(*names, purpose=f"the {side} {limb}")
        return tuple(self._map[n] for n in names)  # type: ignore[return-value]

    def side_of(self, joint: str) -> Literal["left", "right"] | None:
        """The side whose limb roles include ``joint`` (None for the trunk and unknown joints)."""
        for role, value in self._map.items():
            if value == joint and role.split("_")[0] in SIDES:
                return role.split("_")[0]  # type: ignore[return-value]
        return None


def _missing_message(roles: Roles, missing: list[str], purpose: str = "") -> str:
    found = ", ".join(f"{k}={v!r}" for k, v in roles.items()) or "nothing"
    call = ", ".join(f'{r}="..."' for r in missing if r != "spine")
    why = f" for {purpose}" if purpose else ""
    return (
        f"Could not infer the joint role(s) {missing}{why}. Found: {found}. "
        f"Name the joints yourself: skeleton.with_roles({call}) (or pass roles={{...}}); "
        f"joints are {list(roles._names)[:40]}{' ...' if len(roles._names) > 40 else ''}"
    )


# ---------------------------------------------------------------- inference
class _Tree:
    """Hierarchy helpers over a skeleton's arrays."""

    def __init__(self, names: tuple[str, ...], parents: NDArray[np.int64], offsets: NDArray[np.float64]):
        self.names = names
        self.parents = [int(p) for p in parents]
        self.lengths = np.linalg.norm(offsets, axis=-1)
        self.children: list[list[int]] = [[] for _ in names]
        for j, p in enumerate(self.parents):
            if p >= 0:
                self.children[p].append(j)
        scale = float(np.max(self.lengths)) if len(self.lengths) else 1.0
        self.eps = 1e-6 * max(scale, 1e-12)

    def ancestors(self, j: int) -> list[int]:
        out = []
        while self.parents[j] >= 0:
            j = self.parents[j]
            out.append(j)
        return out

    def is_ancestor(self, a: int, j: int) -> bool:
        return a in self.ancestors(j)

    def distinct_parent(self, j: int) -> int:
        """Nearest ancestor of ``j`` not at ``j``'s own place (-1 if none)."""
        k = j
        while self.parents[k] >= 0:
            if self.lengths[k] > self.eps:
                return self.parents[k]
            k = self.parents[k]
        return -1

    def lca(self, a: int, b: int) -> int:
        up = set([a] + self.ancestors(a))
        for k in [b] + self.ancestors(b):
            if k in up:
                return k
        return 0

    def path(self, top: int, bottom: int) -> list[int]:
        """Joints from ``top`` down to ``bottom`` (both included)."""
        chain = [bottom]
        while chain[-1] != top:
            chain.append(self.parents[chain[-1]])
        return chain[::-1]

    def descendants(self, j: int) -> list[int]:
        out, stack = [], list(self.children[j])
        while stack:
            k = stack.pop()
            out.append(k)
            stack.extend(self.children[k])
        return sorted(out)


def _rest_pose(skeleton: Skeleton) -> NDArray[np.float64]:
    pos = np.zeros((skeleton.n_joints, 3))
    for j in range(1, skeleton.n_joints):
        pos[j] = pos[skeleton.parents[j]] + skeleton.offsets[j]
    return pos


def infer_roles(
    skeleton: Skeleton,
    *,
    overrides: Mapping[str, Any] | None = None,
    pose: NDArray[np.float64] | None = None,
) -> Roles:
    """Infer the joint roles of a skeleton (see the module docstring).

    Parameters
    ----------
    skeleton : Skeleton
    overrides : mapping of role name to joint name, optional
        Roles fixed by the user; the others are inferred around them.
    pose : ndarray, shape (J, 3) or (F, J, 3), optional
        World joint positions of one or more frames for the geometric
        checks (default: the rest pose).

    Returns
    -------
    Roles

    Raises
    ------
    RolesError
        For a skeleton that is plainly not a biped human (a quadruped, a
        hand: see :func:`not_a_biped`) when no role is given in
        ``overrides``; naming the roles yourself is the way out.

    Examples
    --------
    >>> import mocaplab as ml
    >>> roles = infer_roles(ml.cmu("16_15").skeleton)
    >>> roles["left_knee"], roles["spine"]
    ('LeftLeg', ('LowerBack', 'Spine', 'Spine1'))
    """
    result = _infer(skeleton, overrides=overrides, pose=pose)
    for note in result.notes:
        warn(note, RolesWarning)
    return result


def _infer(
    skeleton: Skeleton,
    *,
    overrides: Mapping[str, Any] | None = None,
    pose: NDArray[np.float64] | None = None,
) -> Roles:
    """:func:`infer_roles` without its warnings (the notes are kept on the result)."""
    names = tuple(skeleton.names)
    tree = _Tree(names, skeleton.parents, skeleton.offsets)
    fixed: dict[str, Any] = dict(overrides or {})
    Roles(names, fixed)  # validates the override names
    notes: list[str] = []
    idx = {n: i for i, n in enumerate(names)}
    parsed = [_parse(n) for n in names]
    kinds = [_kinds(base) for _, base, _ in parsed]
    sides = [side for side, _, _ in parsed]
    roles: dict[str, int] = {k: idx[v] for k, v in fixed.items() if k != "spine"}

    def named(kind: str, side: str | None, among: list[int] | None = None) -> list[int]:
        cands = [j for j in (range(len(names)) if among is None else among) if kind in kinds[j] and sides[j] == side]
        return sorted(cands, key=lambda j: (kinds[j][kind], len(tree.ancestors(j))))

    def nearest_named_ancestor(j: int, kind: str, stop: set[int]) -> int:
        for a in tree.ancestors(j):
            if a in stop:
                break
            if kind in kinds[a]:
                return a
        return -1

    # ---- limbs anchored by names
    for side in SIDES:
        for end, limb in (("ankle", ("hip", "knee")), ("wrist", ("shoulder", "elbow"))):
            key = f"{side}_{end}"
            if key not in roles:
                cands = named(end, side)
                if end == "ankle":  # a foot word below another foot word is the toe (SMPL left_foot)
                    cands = [j for j in cands if not any(tree.is_ancestor(k, j) for k in cands if k != j)] or cands
                if cands:
                    roles[key] = cands[0]
            if key not in roles:
                continue
            below = roles[key]
            for part in reversed(limb):
                k2 = f"{side}_{part}"
                if k2 not in roles:
                    j = nearest_named_ancestor(below, part, stop=set())
                    if j < 0 or j == below:
                        j = tree.distinct_parent(below)
                    if j < 0:
                        break
                    roles[k2] = j
                below = roles[k2]

    # ---- geometric fallback for legs / arms without names
    rest = _rest_pose(skeleton)
    frames = rest[None] if pose is None else np.asarray(pose, dtype=float).reshape(-1, len(names), 3)
    if not fixed:
        why = _not_a_biped(tree, frames, parsed, kinds)
        if why is not None:
            raise RolesError(
                f"This skeleton is not a biped human: {why}. Joint roles (pelvis, legs, arms, head) are a "
                "human's; to use it anyway, name the joints that play them: skeleton.with_roles(pelvis=..., "
                "left_ankle=..., ...) or roles={...} in mocaplab.load and every function that takes roles="
            )
    if not all(f"{s}_ankle" in roles for s in SIDES):
        _legs_from_geometry(tree, frames, roles, notes)
    if not all(f"{s}_wrist" in roles for s in SIDES) and all(f"{s}_hip" in roles for s in SIDES):
        _arms_from_geometry(tree, frames, roles, notes, kinds)

    # ---- toes
    for side in SIDES:
        a, key = roles.get(f"{side}_ankle"), f"{side}_toe"
        if a is None or key in roles:
            continue
        under = tree.descendants(a)
        # a toe word first (LeftToeBase), else a foot word below the ankle (SMPL left_foot)
        toes = [j for j in under if "toe" in kinds[j] and "ankle" not in kinds[j]] or [
            j for j in under if "toe" in kinds[j]
        ]
        if toes:
            roles[key] = min(toes, key=lambda j: len(tree.ancestors(j)))
        elif len(tree.children[a]) == 1 and tree.lengths[tree.children[a][0]] > tree.eps:
            roles[key] = tree.children[a][0]

    # ---- pelvis, head, neck, spine
    if "pelvis" not in roles and all(f"{s}_hip" in roles for s in SIDES):
        roles["pelvis"] = tree.lca(roles["left_hip"], roles["right_hip"])
    if "pelvis" not in roles:
        cands = named("pelvis", None)
        if cands:
            roles["pelvis"] = cands[0]
    pelvis = roles.get("pelvis")
    if "head" not in roles and pelvis is not None:
        cands = [j for j in named("head", None) if tree.is_ancestor(pelvis, j)]
        if cands:
            roles["head"] = cands[0]
    if "head" not in roles and pelvis is not None:
        _head_from_neck(tree, roles, notes, kinds, named("neck", None))
    if "head" not in roles and pelvis is not None:
        _head_from_geometry(tree, frames, roles, notes, kinds)
    head = roles.get("head")
    if "neck" not in roles and head is not None and pelvis is not None:
        on_path = tree.path(pelvis, head)[1:-1]
        # the head itself when it is the last neck joint (a chain that ends at the neck)
        necks = [j for j in on_path + [head] if "neck" in kinds[j]]
        if necks:
            roles["neck"] = necks[0]
        else:
            # where the arms leave the trunk: the neck starts just above
            branch = [
                next(a for a in tree.ancestors(roles[f"{s}_shoulder"]) if a in on_path or a == pelvis)
                for s in SIDES
                if f"{s}_shoulder" in roles and tree.is_ancestor(pelvis, roles[f"{s}_shoulder"])
            ]
            above = [j for j in on_path if any(tree.is_ancestor(b, j) for b in branch)]
            roles["neck"] = above[0] if above else (on_path[-1] if on_path else head)
    # ---- clavicles: between the shoulder and the spine
    if pelvis is not None and "neck" in roles:
        trunk = set(tree.path(pelvis, roles["neck"]))
        for side in SIDES:
            sh, key = roles.get(f"{side}_shoulder"), f"{side}_clavicle"
            if sh is None or key in roles:
                continue
            chain = [a for a in tree.ancestors(sh) if a not in trunk]
            named_clav = [a for a in chain if "clavicle" in kinds[a]]
            if named_clav:
                roles[key] = named_clav[0]
            elif chain and tree.parents[chain[-1]] in trunk:
                roles[key] = chain[-1]

    # ---- geometric checks: legs below the pelvis, sides from the facing direction
    _check_sides(tree, frames, roles, notes, fixed)

    out: dict[str, Any] = {k: names[v] for k, v in roles.items()}
    if "spine" in fixed:
        out["spine"] = tuple(fixed["spine"])
    elif pelvis is not None and "neck" in roles and tree.is_ancestor(pelvis, roles["neck"]):
        out["spine"] = tuple(names[j] for j in tree.path(pelvis, roles["neck"])[1:-1])
    return Roles(names, out, tuple(notes))


def _plausible(frames: NDArray[np.float64], roles: dict[str, int]) -> bool:
    """Whether the frames show an upright body (head or neck well above the pelvis)."""
    pelvis = roles.get("pelvis")
    top = roles.get("head", roles.get("neck"))
    if pelvis is None or top is None:
        return False
    rise = frames[:, top, 1] - frames[:, pelvis, 1]
    span = np.linalg.norm(frames[:, top] - frames[:, pelvis], axis=-1)
    return bool(np.median(rise) > 0.8 * np.median(span) > 0)


#: Words of finger joints (searched inside a joint's base word: ``RingFinger2``, ``LeftHandIndex1``).
_FINGER_WORDS = ("thumb", "index", "middle", "ring", "pinky", "little", "finger")
#: Share of the rest pose's height within which a limb's end counts as on the ground.
GROUND_BAND = 0.1


def _not_a_biped(
    tree: _Tree,
    frames: NDArray[np.float64],
    parsed: Sequence[tuple[str | None, str, Any]],
    kinds: list[dict[str, int]],
) -> str | None:
    """Why the skeleton is plainly not a biped human, or None.

    * **A hand**: at least four finger chains (joints named like fingers
      whose parent is not one) and no joint named like a leg (knee, ankle).
    * **More than two legs** (a quadruped, a spider, a hand with its
      fingers hanging): in an upright pose (its height at least a fifth of
      its largest side), more than two limbs reach the ground.  A limb's
      end reaches the ground when it lies within :data:`GROUND_BAND` of the
      height of the lowest joint, and two ends belong to the same limb when
      the joint they branch from is low too (a toe and a heel of one foot);
      a limb is a chain of at least two bones hanging from a joint in the
      upper part of the figure (not a ground marker under a root).
    """
    n = len(tree.names)
    finger = [any(w in base for w in _FINGER_WORDS) for _, base, _ in parsed]
    chains = [j for j in range(n) if finger[j] and (tree.parents[j] < 0 or not finger[tree.parents[j]])]
    legs_named = any("knee" in k or "ankle" in k for k in kinds)
    if len(chains) >= 4 and not legs_named and sum(finger) >= n // 2:
        return f"it looks like a hand ({len(chains)} finger chains: {[tree.names[j] for j in chains[:5]]}, no legs)"
    height = frames[..., 1].mean(axis=0)
    extent = np.ptp(frames.mean(axis=0), axis=0)
    tall = float(extent[1])
    if not (np.isfinite(tall) and tall > 0.2 * float(extent.max()) > 0):
        return None  # not an upright pose: nothing to judge by
    low = float(height.min())
    leaves = [j for j in range(n) if not tree.children[j] and height[j] - low <= GROUND_BAND * tall]
    feet: list[list[int]] = []
    for leaf in leaves:
        # a limb: at least two bones from the leaf up to the upper part of the figure
        bones, k = 0, leaf
        while tree.parents[k] >= 0 and height[k] - low <= 0.4 * tall:
            bones += tree.lengths[k] > tree.eps
            k = tree.parents[k]
        if bones < 2 or height[k] - low <= 0.4 * tall:
            continue
        for foot in feet:
            if height[tree.lca(foot[0], leaf)] - low <= 0.25 * tall:  # they branch at an ankle, not a pelvis
                foot.append(leaf)
                break
        else:
            feet.append([leaf])
    if len(feet) > 2:
        ends = [tree.names[f[0]] for f in feet]
        return f"{len(feet)} limbs reach the ground in its pose ({ends[:6]}), a biped stands on two"
    return None


def _two_bones(tree: _Tree, chain: list[int]) -> tuple[int, int, int] | None:
    """(upper, middle, end) of the two longest consecutive bones along ``chain``."""
    best, pick = -1.0, None
    for i in range(1, len(chain) - 1):
        mid, end = chain[i], chain[i + 1]
        up = tree.distinct_parent(mid)
        if up < 0 or up not in chain:
            continue
        score = tree.lengths[mid] + tree.lengths[end]
        if tree.lengths[mid] > tree.eps and tree.lengths[end] > tree.eps and score > best:
            best, pick = score, (up, mid, end)
    return pick


def _legs_from_geometry(tree: _Tree, frames: NDArray[np.float64], roles: dict[str, int], notes: list[str]) -> None:
    height = frames[..., 1].mean(axis=0)
    leaves = sorted((j for j, c in enumerate(tree.children) if not c), key=lambda j: height[j])
    for i, a in enumerate(leaves):
        for b in leaves[i + 1 :]:
            top = tree.lca(a, b)
            ca, cb = tree.path(top, a)[1:], tree.path(top, b)[1:]
            if len(ca) < 3 or len(cb) < 3 or height[top] <= max(height[a], height[b]):
                continue
            la, lb = _two_bones(tree, [top] + ca), _two_bones(tree, [top] + cb)
            if la is None or lb is None:
                continue
            # left is decided later from the facing direction
            for side, limb in zip(SIDES, (la, lb), strict=True):
                for part, j in zip(("hip", "knee", "ankle"), limb, strict=True):
                    roles.setdefault(f"{side}_{part}", j)
            notes.append(
                f"Legs found from geometry (no joint named like an ankle): "
                f"{tree.names[la[2]]!r} and {tree.names[lb[2]]!r}"
            )
            return


def _arms_from_geometry(
    tree: _Tree, frames: NDArray[np.float64], roles: dict[str, int], notes: list[str], kinds: list[dict[str, int]]
) -> None:
    pelvis = tree.lca(roles["left_hip"], roles["right_hip"])
    legs = set(tree.descendants(roles["left_hip"])) | set(tree.descendants(roles["right_hip"]))
    legs |= {roles["left_hip"], roles["right_hip"]}
    upper = [j for j in tree.descendants(pelvis) if j not in legs]
    leaves = [j for j in upper if not tree.children[j]]
    if len(leaves) < 3:  # two arms and a head at least
        return
    # The arms are the pair of side chains whose shorter two-bone limb is the
    # longest: not "everything but the highest chain", which in a T-pose can
    # be a hand (a HumanIK clavicle rises above a neck that ends the chain).
    depth = {j: len(tree.ancestors(j)) for j in leaves}
    leaves = sorted(leaves, key=lambda j: -depth[j])[:40]  # fingertips and the head first; bounded work
    best, arms = 0.0, []
    for i, a in enumerate(leaves):
        for b in leaves[i + 1 :]:
            top = tree.lca(a, b)
            ca, cb = tree.path(top, a), tree.path(top, b)
            if len(ca) < 4 or len(cb) < 4:  # three joints below the branch on each side
                continue
            la, lb = _two_bones(tree, ca), _two_bones(tree, cb)
            if la is None or lb is None or la == lb:
                continue
            reach = min(tree.lengths[la[1]] + tree.lengths[la[2]], tree.lengths[lb[1]] + tree.lengths[lb[2]])
            if reach > best:
                best, arms = reach, [la, lb]
    if len(arms) == 2:
        # each arm on the side of the leg whose hip it is nearer (the sides of both are settled later, together)
        across_hips = frames[:, roles["left_hip"]] - frames[:, roles["right_hip"]]
        across_arms = frames[:, arms[0][0]] - frames[:, arms[1][0]]
        if np.median(np.einsum("fi,fi->f", across_hips, across_arms)) < 0:
            arms.reverse()
        for side, limb in zip(SIDES, arms, strict=True):
            for part, j in zip(("shoulder", "elbow", "wrist"), limb, strict=True):
                roles.setdefault(f"{side}_{part}", j)
        notes.append(f"Arms found from geometry: {tree.names[arms[0][2]]!r} and {tree.names[arms[1][2]]!r}")


def _arm_joints(tree: _Tree, roles: dict[str, int]) -> set[int]:
    """The limb joints found so far with the joints of each arm's own branch (a clavicle, named or not).

    An arm's branch runs from the shoulder up to the joint the two arms
    share (the chest), that joint excluded; with one arm known, up to the
    nearest ancestor with another child on the trunk side.
    """
    out = {roles[k] for k in roles if k.endswith(LIMB_PARTS)}
    shoulders = [roles[f"{s}_shoulder"] for s in SIDES if f"{s}_shoulder" in roles]
    chest = tree.lca(*shoulders) if len(shoulders) == 2 else -1
    for sh in shoulders:
        for a in tree.ancestors(sh):
            if a == chest or (chest < 0 and len(tree.children[a]) > 1):
                break
            out.add(a)
    return out


def _head_from_neck(
    tree: _Tree, roles: dict[str, int], notes: list[str], kinds: list[dict[str, int]], necks: list[int]
) -> None:
    """A chain that ends at the neck (MotionBuilder HumanIK without a Head joint): its last neck joint is the head.

    Its end site (or child) marks the top of the head, which is what the
    head role stands for.  Never an arm joint.
    """
    arms = _arm_joints(tree, roles)
    pelvis = roles["pelvis"]
    necks = [j for j in necks if tree.is_ancestor(pelvis, j) and not (set(tree.path(pelvis, j)) & arms)]
    if not necks:
        return
    last = max(necks, key=lambda j: len(tree.ancestors(j)))
    if not any(kinds[k] for k in tree.descendants(last)):  # no body-part word below it
        roles["head"] = last
        notes.append(
            f"No head joint: the head is the last neck joint {tree.names[last]!r} "
            "(its end site marks the top of the head)"
        )


def _head_from_geometry(
    tree: _Tree, frames: NDArray[np.float64], roles: dict[str, int], notes: list[str], kinds: list[dict[str, int]]
) -> None:
    if not all(f"{s}_hip" in roles for s in SIDES):
        return
    pelvis = roles["pelvis"]
    arms = _arm_joints(tree, roles)  # legs and arms, clavicles included: never the head
    limb_words = set(LIMB_PARTS)
    height = frames[..., 1].mean(axis=0)
    cands = [
        j
        for j in tree.descendants(pelvis)
        if not (set(tree.path(pelvis, j)) & arms)
        and not (limb_words & set(kinds[j]))
        and tree.lengths[j] > tree.eps
        and height[j] > height[pelvis]
    ]
    if not cands:
        return
    top = max(cands, key=lambda j: height[j])
    # the head joint is the last one with a bone of its own, not an end site
    roles["head"] = top
    notes.append(f"Head found from geometry: {tree.names[top]!r}")


def _check_sides(
    tree: _Tree, frames: NDArray[np.float64], roles: dict[str, int], notes: list[str], fixed: Mapping[str, Any]
) -> None:
    if not _plausible(frames, roles) or not all(f"{s}_ankle" in roles for s in SIDES):
        return
    pelvis = frames[:, roles["pelvis"]]
    for s in SIDES:
        if np.median(frames[:, roles[f"{s}_ankle"], 1] - pelvis[:, 1]) >= 0:
            raise RolesError(
                f"The {s} ankle {tree.names[roles[f'{s}_ankle']]!r} is not below the pelvis "
                f"{tree.names[roles['pelvis']]!r}; name the leg joints with skeleton.with_roles(...)"
            )
    if any(k.startswith(SIDES) for k in fixed):
        return  # the user said which side is which
    up = frames[:, roles.get("head", roles.get("neck", roles["pelvis"]))] - pelvis
    fwd = []
    for s in SIDES:
        if f"{s}_toe" in roles:
            fwd.append(frames[:, roles[f"{s}_toe"]] - frames[:, roles[f"{s}_ankle"]])
    if not fwd:
        return
    forward = np.mean(fwd, axis=0)
    forward = forward - (np.einsum("fi,fi->f", forward, up) / np.maximum(np.einsum("fi,fi->f", up, up), 1e-12))[:, None] * up
    left_dir = np.cross(up, forward)
    across = frames[:, roles["left_hip"]] - frames[:, roles["right_hip"]]
    cos = np.einsum("fi,fi->f", left_dir, across) / np.maximum(
        np.linalg.norm(left_dir, axis=-1) * np.linalg.norm(across, axis=-1), 1e-12
    )
    c = float(np.median(cos))
    if c < -0.5:
        for part in LIMB_PARTS:
            a, b = roles.pop(f"left_{part}", None), roles.pop(f"right_{part}", None)
            if b is not None:
                roles[f"left_{part}"] = b
            if a is not None:
                roles[f"right_{part}"] = a
        if _parse(tree.names[roles["left_hip"]])[0] is None:
            return  # sides found from geometry, now put the right way round: nothing to report
        notes.append(
            "Left and right swapped: the joints named as left are on the body's right side "
            f"(facing along the toes); left hip is now {tree.names[roles['left_hip']]!r}"
        )


def resolve_roles(skeleton_or_motion: Any, roles: Mapping[str, Any] | None = None) -> Roles:
    """The roles of a skeleton (or a motion's), with optional overrides.

    Every entry point that needs roles accepts ``roles=`` and calls this:
    ``None`` gives ``skeleton.roles``; a mapping of role names to joint names
    overrides those roles (the rest is inferred around them); a
    :class:`Roles` is used as it is.

    Parameters
    ----------
    skeleton_or_motion : Skeleton or Motion
    roles : mapping of role name to joint name, or Roles, optional
        The overrides; default none.

    Returns
    -------
    Roles

    Raises
    ------
    TypeError
        If ``roles`` is not a mapping.
    RolesError
        If an override names an unknown role or joint.

    Examples
    --------
    >>> import mocaplab as ml
    >>> walk = ml.cmu("16_15")
    >>> resolve_roles(walk)["left_toe"], resolve_roles(walk, {"left_toe": "LeftFoot"})["left_toe"]
    ('LeftToeBase', 'LeftFoot')
    """
    sk = getattr(skeleton_or_motion, "skeleton", skeleton_or_motion)
    if isinstance(roles, Roles):
        return roles
    if roles is None:
        return sk.roles  # type: ignore[no-any-return]
    if not isinstance(roles, Mapping):
        raise TypeError(f"Expected `roles` to be a mapping of role names to joint names, got {type(roles).__name__}")
    return sk.with_roles(**roles).roles  # type: ignore[no-any-return]


# ------------------------------------------------------------------ mirror
def mirror_map(skeleton: Skeleton, roles: Roles | None = None) -> NDArray[np.int64]:
    """For each joint, its left/right counterpart (itself on the midline).

    Pairs come, in this order, from the limb roles (``left_knee`` with
    ``right_knee``), from the two sides' limb subtrees matched joint by joint
    when they have the same shape (fingers and helper joints whose names
    carry no side), and from the names (:func:`mirror_name`).

    Parameters
    ----------
    skeleton : Skeleton
    roles : Roles, optional
        Default the skeleton's own (none when they cannot be inferred: then
        the names alone pair the joints).

    Returns
    -------
    ndarray of int64, shape (J,)
        ``out[j]`` is the index of joint ``j``'s counterpart; applying it
        twice gives every joint back.

    Examples
    --------
    >>> import mocaplab as ml
    >>> sk = ml.cmu("16_15").skeleton
    >>> pairs = mirror_map(sk)
    >>> sk.names[pairs[sk.index("LeftUpLeg")]], int(pairs[0])
    ('RightUpLeg', 0)
    """
    names = tuple(skeleton.names)
    tree = _Tree(names, skeleton.parents, skeleton.offsets)
    out = np.arange(len(names), dtype=np.int64)
    done = np.zeros(len(names), dtype=bool)

    def pair(a: int, b: int) -> None:
        if not done[a] and not done[b] and a != b:
            out[a], out[b] = b, a
            done[a] = done[b] = True

    if roles is None:
        try:
            roles = skeleton.roles
        except RolesError:
            roles = None
    if roles is not None:
        for part in LIMB_PARTS:
            if f"left_{part}" in roles and f"right_{part}" in roles:
                pair(roles.index(f"left_{part}"), roles.index(f"right_{part}"))
        # the subtrees of the limbs' top joints, matched by shape
        for part in ("hip", "clavicle", "shoulder"):
            if f"left_{part}" in roles and f"right_{part}" in roles:
                la, ra = _shape_walk(tree, roles.index(f"left_{part}")), _shape_walk(tree, roles.index(f"right_{part}"))
                if [len(tree.children[j]) for j in la] == [len(tree.children[j]) for j in ra]:
                    for a, b in zip(la, ra, strict=True):
                        pair(a, b)
    lookup = {n: i for i, n in enumerate(names)}
    for i, n in enumerate(names):
        j = lookup.get(mirror_name(n))
        if j is not None:
            pair(i, j)
    # the helper joints above two paired joints (CMU LHipJoint, Daz lButtock)
    for i in range(len(names)):
        if done[i] and out[i] != i:
            pi, pj = tree.parents[i], tree.parents[int(out[i])]
            if pi >= 0 and pj >= 0 and pi != pj and len(tree.children[pi]) == 1 and len(tree.children[pj]) == 1:
                pair(pi, pj)
    return out


def _shape_walk(tree: _Tree, top: int) -> list[int]:
    """Joints of a subtree in depth-first order (children in index order)."""
    order = []
    stack = [top]
    while stack:
        j = stack.pop()
        order.append(j)
        stack.extend(reversed(tree.children[j]))
    return order
