"""The staggered pose representation (Coleman et al. 2008, section 3).

A motion is a sparse sequence of staggered poses ``S_k`` at times ``t_k``.
Each pose holds, for every *control variable* ``i``, a value ``v_{k,i}`` and a
timing refinement ``r_{k,i}``; the equivalent spline knot is
``(t_k + r_{k,i}, v_{k,i})``.

Control variables
-----------------
For a skeleton of ``J`` joints whose clip animates the local translations
of ``T`` joints besides the root, there are ``V = J + 1 + T`` variables, in
this order:

* variable ``0``: the root translation (metres), name ``"root_position"``
  (:attr:`~mocaplab.motion.Motion.root_positions`);
* variable ``1 + j``: the local rotation of joint ``j`` (unit quaternion),
  named after the joint (variable 1 is the root orientation);
* variable ``J + 1 + m``: the local translation (metres, in the parent's
  frame) of joint ``translation_joints[m]``, named ``"<joint>.position"``:
  the per-joint translation channels of :attr:`~mocaplab.motion.Motion.translations`
  that change over the clip (:func:`translation_joints`), for instance a
  pelvis travelling below a static reference joint 0.  They are evaluated
  exactly like the root translation.  Translations that never change are
  kept as :attr:`StaggeredMotion.rest_translations` and written back on
  every frame, so evaluation returns a Motion with ``translations``
  whenever the source clip had them.

The root translation and the translation variables are the *position
variables* (``P = 1 + T`` of them, columns :attr:`StaggeredMotion.position_columns`);
internally they are handled as one block of shape (..., P, 3).

Concatenation and factorisation (the paper's ``+`` in a circle and ``-`` in a
circle)
-------------------------------------------------------------------------------
For translations ``a (+) b = a + b`` and ``c (-) a = c - a``.  For rotations
``a (+) b = quat.mul(a, b)`` and ``c (-) a = quat.mul(quat.inv(a), c)``:
``b`` is applied *after* ``a`` in ``a``'s own (body) frame, the intrinsic order
used by motion displacement maps, so ``a (+) (c (-) a) == c``.  The order
matters for rotations and is fixed everywhere in this package.

Evaluation (section 3)
----------------------
Variable ``i`` at time ``t`` lies between its refined knots
``T_k = t_k + r_{k,i}`` and ``T_{k+1}``; with the normalised time
``t' = (t - T_k) / (T_{k+1} - T_k)`` its value is

    v_i(t) = s_i(t') (+) d_i(t')

where ``s_i`` is a cubic spline and ``d_i`` a displacement map, both defined on
``t'`` so that moving knots in time warps them with the knots.

* Translation splines (the root and every translation variable) are cubic
  Bezier curves with end points ``v_k`` and ``v_{k+1}``; the inner control
  points are stored *relative to* their end points (``P1 = v_k + a``,
  ``P2 = v_{k+1} + b``) so a moved knot carries its tangent with it.
* Rotation splines are Shoemake's cubic quaternion Bezier curves evaluated by
  recursive spherical linear interpolation (de Casteljau with slerp), with
  control orientations ``q1 = v_k``, ``q2 = v_k (+) alpha``,
  ``q3 = v_{k+1} (+) beta``, ``q4 = v_{k+1}``.
* Displacement maps are dense samples on the normalised time of their
  segment (the frames of the clip they were measured on).  Translation
  displacements are vectors; rotation displacements are stored as rotation
  vectors ``log(d)``.  Between samples they are interpolated linearly; on a
  sample they are returned exactly, which is what makes extraction followed by
  evaluation reproduce a clip to rounding error.
* Before a variable's first knot and after its last one the value is held.

Noise layer (section 6)
-----------------------
Timing edits pull apart the capture noise of sequential joints, which
otherwise cancels on their descendants; the paper filters rotations before
editing.  :func:`~mocaplab.staggered.extract` fits the layers above to
filtered rotations and keeps what the filter removed as a last rotation
layer ``n_i`` on the *pose timing* shared by all joints,

    v_i(t) = s_i(t') (+) d_i(t') (+) n_i(u(t)),
    u(t) = k + (t - t_k) / (t_{k+1} - t_k)   for t_k <= t < t_{k+1},

so the clip is still reproduced exactly and the noise moves with the poses
but not with the refinements (:mod:`mocaplab.staggered.noise`).  What the
filter removed from a sharp motion (a flick faster than its band) is not
noise: it is a *sharp layer* ``h_i`` sampled like the displacement maps, on
each variable's own normalised time, so it moves with the variable's knots
(:func:`~mocaplab.staggered.noise.sharp_detail`):

    v_i(t) = s_i(t') (+) d_i(t') (+) h_i(t') (+) n_i(u(t)).

Geometric edits leave it alone, as they leave the displacement maps.  The true
pose at ``t_k`` includes both; extreme values include neither.

Partial poses (section 6) control a subset of the variables: ``active[k, i]``
says whether pose ``k`` has a knot for variable ``i``; a variable's spline
runs between consecutive *active* knots.

Editing knots (section 3, Figure 3b): for every active knot with
``r_{k,i} != 0`` there is an editing knot at the pose time ``t_k`` whose value
is the true value of the variable at ``t_k``.  Here an editing knot is not
stored: its value is always obtained by evaluation (so it is re-created at
``t_k`` after every retiming, as in Figure 6c), and geometric edits
(:mod:`mocaplab.staggered.edit`) use its position to give the editing knot and
the extreme knot equal changes.

Where this module sits
----------------------
It is the ground floor of :mod:`mocaplab.staggered`: it imports only the
kinematic core, and every other module of the package builds on it
(:mod:`~mocaplab.staggered.features`, :mod:`~mocaplab.staggered.noise`,
:mod:`~mocaplab.staggered.constraints`, :mod:`~mocaplab.staggered.fit`,
:mod:`~mocaplab.staggered.edit`, :mod:`~mocaplab.staggered.editor`).  The
edits of section 5 are functions up there, not methods here; the only change
made here is :func:`set_refinements`, which owns the evaluation caches it
keeps.  Longer than 800 lines because :class:`StaggeredMotion` is one
container whose evaluation (splines, displacement maps, the noise layer,
editing knots and the caches that make edits cheap) reads its own arrays
throughout; splitting the evaluation from the container would spread the one
equation of section 3 over two files that each need the other's internals.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from functools import cached_property
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import quat
from .._api import Gone
from .._warnings import warn
from ..motion import Motion, Skeleton, readonly

__all__ = [
    "StaggeredMotion",
    "StaggeredTimingWarning",
    "ROOT_POSITION",
    "compose_rotation",
    "factor_rotation",
    "slerp_unit",
    "bezier",
    "quat_bezier",
    "variable_names",
    "translation_joints",
    "TRANSLATION_SUFFIX",
    "TRANSLATION_TOLERANCE",
    "locate",
    "next_active",
    "casteljau",
    "pose_u",
    "pose_time",
    "set_refinements",
]

Array = NDArray[np.float64]

ROOT_POSITION = "root_position"
"""Name of control variable 0, the root translation."""

TRANSLATION_SUFFIX = ".position"
"""Suffix of the names of the translation variables (``"Hips.position"``)."""

TRANSLATION_TOLERANCE = 1e-6
"""Metres: a translation channel that never moves farther than this from its first frame is constant
(:func:`translation_joints`)."""


class StaggeredTimingWarning(UserWarning):
    """A refined knot time came closer to a neighbouring pose than to its own
    pose (section 5.2): large nonlinear time warps may add sudden accelerations.

    Raised through :func:`mocaplab._warnings.warn` by :func:`set_refinements`, so every timing edit
    (:func:`~mocaplab.staggered.succession`, :func:`~mocaplab.staggered.retime`, ...) may emit it;
    silence it with :func:`warnings.simplefilter` or turn it into an error while testing.

    Parameters
    ----------
    *args
        The message, as for any warning.

    Examples
    --------
    >>> import warnings
    >>> from mocaplab.staggered import StaggeredTimingWarning
    >>> issubclass(StaggeredTimingWarning, UserWarning)
    True
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("error", StaggeredTimingWarning)  # a close knot now raises
    """


# --------------------------------------------------------------------- kernels
def compose_rotation(a: ArrayLike, b: ArrayLike) -> Array:
    """``a (+) b`` for rotations: ``quat.mul(a, b)`` (``b`` applied after ``a``, in ``a``'s frame).

    Parameters
    ----------
    a, b : array_like, shape (..., 4)
        Unit quaternions ``(x, y, z, w)``, broadcasting.

    Returns
    -------
    ndarray, shape (..., 4)

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.spatial.transform import Rotation
    >>> from mocaplab.staggered import compose_rotation, factor_rotation
    >>> a, b = Rotation.from_euler("zx", [[30, 0], [0, 45]], degrees=True).as_quat()
    >>> bool(np.allclose(factor_rotation(compose_rotation(a, b), a), b))
    True
    """
    return quat.mul(a, b)


def factor_rotation(c: ArrayLike, a: ArrayLike) -> Array:
    """``c (-) a`` for rotations: the ``b`` with ``a (+) b == c``, i.e. ``inv(a) * c``.

    Parameters
    ----------
    c, a : array_like, shape (..., 4)
        Unit quaternions ``(x, y, z, w)``, broadcasting.

    Returns
    -------
    ndarray, shape (..., 4)
        The rotation ``b`` that :func:`compose_rotation` adds to ``a`` to give ``c``.

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.spatial.transform import Rotation
    >>> from mocaplab.staggered import factor_rotation
    >>> a, c = Rotation.from_euler("z", [[30], [75]], degrees=True).as_quat()
    >>> round(float(np.degrees(Rotation.from_quat(factor_rotation(c, a)).magnitude())), 6)
    45.0
    """
    return quat.mul(quat.inv(a), c)


def slerp_unit(a: Array, b: Array, t: Array, *, unit: bool = False) -> Array:
    """Spherical linear interpolation *without* a shortest-arc sign flip.

    Parameters
    ----------
    a, b : ndarray, shape (..., 4)
        Quaternions.  With ``unit=False`` they may have any length: the angle
        is taken between their directions and the result interpolates their
        lengths too (the Appendix A objective needs this while its control
        points are not yet unit).
    t : ndarray, shape (...,)
        Interpolation parameter (0 gives ``a``, 1 gives ``b``).
    unit : bool
        Promise that ``a`` and ``b`` are unit (skips two norms).

    Returns
    -------
    ndarray, shape (..., 4)

    Notes
    -----
    Spline control orientations are kept in one hemisphere, so flipping ``b``
    to the shorter arc inside the recursive construction is neither needed nor
    wanted (it would make the curve jump where a dot product changes sign).
    """
    dot = np.einsum("...i,...i->...", a, b)
    if not unit:
        na = np.sqrt(np.einsum("...i,...i->...", a, a))
        nb = np.sqrt(np.einsum("...i,...i->...", b, b))
        dot = dot / np.maximum(na * nb, 1e-300)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    s = np.sin(theta)
    small = s < 1e-9
    inv = 1.0 / np.where(small, 1.0, s)
    w0 = np.where(small, 1.0 - t, np.sin((1.0 - t) * theta) * inv)
    w1 = np.where(small, t, np.sin(t * theta) * inv)
    return w0[..., None] * a + w1[..., None] * b


def bezier(p0: Array, p1: Array, p2: Array, p3: Array, t: Array) -> Array:
    """Cubic Bezier curve ``sum_j B_j(t) P_j`` (Bernstein basis), broadcasting.

    Parameters
    ----------
    p0, p1, p2, p3 : array_like, shape (..., D)
        Control points: the curve starts at ``p0`` (``t = 0``), ends at ``p3``
        (``t = 1``) and leaves/arrives along ``p1 - p0`` and ``p3 - p2``.
    t : array_like, shape (...,)
        Curve parameters, usually in [0, 1].

    Returns
    -------
    ndarray, shape (..., D)
        The curve points.

    Examples
    --------
    >>> import numpy as np
    >>> from mocaplab.staggered import bezier
    >>> p = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [2.0, 1.0]])
    >>> bezier(*p, 0.5)
    array([1. , 0.5])
    >>> bezier(*p, np.array([0.0, 1.0]))
    array([[0., 0.],
           [2., 1.]])
    """
    t = np.asarray(t, dtype=float)[..., None]
    s = 1.0 - t
    return (s * s * s) * p0 + (3.0 * s * s * t) * p1 + (3.0 * s * t * t) * p2 + (t * t * t) * p3


def quat_bezier(q1: Array, q2: Array, q3: Array, q4: Array, t: Array, *, unit: bool = True) -> Array:
    """Cubic quaternion spline by recursive slerp (Shoemake 1985; Appendix A's ``s``).

    ``s(q1, q2, q3, q4, t)``: de Casteljau's construction with every linear
    interpolation replaced by :func:`slerp_unit`.  Interpolates ``q1`` at
    ``t = 0`` and ``q4`` at ``t = 1``; ``q2`` and ``q3`` are the tangent
    orientations.

    Parameters
    ----------
    q1, q2, q3, q4 : array_like, shape (..., 4)
        Control quaternions ``(x, y, z, w)``: the end orientations ``q1`` and
        ``q4``, the tangent orientations ``q2`` and ``q3``.
    t : array_like, shape (...,)
        Curve parameters in [0, 1].
    unit : bool, default True
        The inputs are unit quaternions and so is the result; ``False``
        accepts control quaternions of any length.

    Returns
    -------
    ndarray, shape (..., 4)

    Examples
    --------
    A curve whose control orientations turn 0, 30, 60 and 90 degrees about y is
    halfway (45 degrees) at ``t = 0.5``:

    >>> import numpy as np
    >>> from scipy.spatial.transform import Rotation
    >>> from mocaplab.staggered import quat_bezier
    >>> q = Rotation.from_euler("y", [[0], [30], [60], [90]], degrees=True).as_quat()
    >>> half = quat_bezier(*q, 0.5)
    >>> round(float(np.degrees(Rotation.from_quat(half).magnitude())), 6)
    45.0
    """
    t = np.asarray(t, dtype=float)
    a = slerp_unit(q1, q2, t, unit=unit)
    b = slerp_unit(q2, q3, t, unit=unit)
    c = slerp_unit(q3, q4, t, unit=unit)
    d = slerp_unit(a, b, t, unit=unit)
    e = slerp_unit(b, c, t, unit=unit)
    return slerp_unit(d, e, t, unit=unit)


def variable_names(skeleton: Skeleton, translation_joints: Sequence[int] = ()) -> tuple[str, ...]:
    """Names of the ``J + 1 + T`` control variables.

    ``("root_position", *joint names, *("<joint>.position" for each translation joint))``.

    Parameters
    ----------
    skeleton : Skeleton
    translation_joints : sequence of int, default ()
        Joints whose local translation is a variable (:func:`translation_joints`).

    Returns
    -------
    tuple of str, length ``J + 1 + T``
        Column names of ``StaggeredMotion.refinements`` and ``.active``.

    Examples
    --------
    >>> from mocaplab.motion import Skeleton
    >>> from mocaplab.staggered import variable_names
    >>> sk = Skeleton(["hips", "knee"], [-1, 0], [[0, 1, 0], [0, -0.5, 0]])
    >>> variable_names(sk, (1,))
    ('root_position', 'hips', 'knee', 'knee.position')
    """
    names = skeleton.names
    return (ROOT_POSITION,) + tuple(names) + tuple(names[int(j)] + TRANSLATION_SUFFIX for j in translation_joints)


def translation_joints(motion: Motion) -> tuple[int, ...]:
    """Joints whose local translation is a control variable: those animated in ``motion``.

    Every joint ``j >= 1`` whose row of :attr:`~mocaplab.motion.Motion.translations`
    moves more than :data:`TRANSLATION_TOLERANCE` (a micrometre) from its
    first frame.  A channel within that is constant (a studio exporter's
    float noise, 1e-12 to 1e-7 m, made three such channels variables of a
    24-variable clip): it is kept as a rest translation, its first frame's,
    and reproduced to within the tolerance (bit for bit when it is exactly
    constant).  Joint 0 is placed by the root translation (its row of
    ``translations`` is ignored by forward kinematics).  Empty when the clip
    has no translation channels.

    Parameters
    ----------
    motion : Motion
        The clip; only its ``translations`` (shape (F, J, 3), metres, or ``None``) are read.

    Returns
    -------
    tuple of int
        Joint indices in increasing order.

    Examples
    --------
    >>> import numpy as np
    >>> from mocaplab.motion import Motion, Skeleton
    >>> sk = Skeleton(["ref", "hips", "knee"], [-1, 0, 1], [[0, 0, 0], [0, 1, 0], [0, -0.5, 0]])
    >>> tr = np.broadcast_to(sk.offsets, (3, 3, 3)).copy()
    >>> tr[:, 1, 0] = [0.0, 0.1, 0.2]  # the hips travel along x below a static joint 0
    >>> translation_joints(Motion(sk, np.tile([0, 0, 0, 1.0], (3, 3, 1)), np.zeros((3, 3)), 30.0, translations=tr))
    (1,)
    """
    tr = motion.translations
    if tr is None:
        return ()
    moving = np.abs(tr - tr[:1]).max(axis=(0, 2)) > TRANSLATION_TOLERANCE
    moving[0] = False
    return tuple(int(j) for j in np.flatnonzero(moving))


def _frame_times(duration: float, fps: float) -> Array:
    n = int(np.floor(duration * fps + 1e-9)) + 1
    return np.arange(n) / fps


# -------------------------------------------------------------- the container
@dataclasses.dataclass(frozen=True, eq=False)
class StaggeredMotion:
    """A motion as staggered poses, splines and displacement maps.

    Build one with :func:`mocaplab.staggered.extract` (from a clip) rather
    than by hand; edit it with the functions of
    :mod:`mocaplab.staggered.edit` (``ml.staggered.succession(sm, 0.02)``),
    which return a new object.

    Parameters
    ----------
    skeleton : Skeleton
    fps : float
        Frame rate of :meth:`evaluate`'s output.
    times : ndarray, shape (K,)
        Pose times ``t_k`` in seconds, strictly increasing.
    refinements : ndarray, shape (K, V)
        Timing refinements ``r_{k,i}`` in seconds (``V = J + 1 + T``, see the
        module notes).
    root_values : ndarray, shape (K, 3)
        Extreme values of the root translation (metres).
    rotation_values : ndarray, shape (K, J, 4)
        Extreme values of the joint rotations (unit quaternions).
    root_tangents : ndarray, shape (K, 2, 3)
        For the segment starting at pose ``k``: ``P1 - v_k`` and ``P2 - v_next``.
    rotation_tangents : ndarray, shape (K, J, 2, 4)
        For the segment starting at pose ``k``: ``alpha`` and ``beta``, with
        ``q2 = v_k (+) alpha`` and ``q3 = v_next (+) beta``.
    sample_u : ndarray, shape (N, V)
        Displacement-map sample positions of each variable, as
        ``k + t' (k_next - k)`` (pose-index units, increasing).
    root_displacement : ndarray, shape (N, 3)
    rotation_displacement : ndarray, shape (N, J, 3)
        Rotation vectors of the rotation displacements.
    active : ndarray of bool, shape (K, V), optional
        Which variables each pose controls (all by default; first and last
        poses must control every variable).
    priorities : ndarray, shape (K,), optional
        Extraction priorities ``w_k`` (``inf`` for the forced first and last
        poses, NaN for poses created by editing).
    name : str
    constraints : ConstraintLayer, optional
        The contact constraint displacement layer (see
        :class:`mocaplab.staggered.constraints.ConstraintLayer`; evaluation
        calls its ``apply``, so this module never imports it).
    translation_joints : tuple of int, length T, optional
        Joints (never joint 0) whose local translation is a control variable
        (variable ``J + 1 + m`` for ``translation_joints[m]``).
    translation_values : ndarray, shape (K, T, 3), optional
        Extreme values of the translation variables (metres, parent frame).
    translation_tangents : ndarray, shape (K, T, 2, 3), optional
        As ``root_tangents``, per translation variable.
    translation_displacement : ndarray, shape (N, T, 3), optional
        As ``root_displacement``, per translation variable.
    rest_translations : ndarray, shape (J, 3), optional
        Local translations of every joint on every frame where no
        translation variable overrides them (the source clip's constant
        translation channels).  ``None``: the clip had no translation
        channels, and evaluation uses the skeleton offsets.
    noise_u : ndarray, shape (M,), optional
        Positions of the noise-layer samples in pose-index units
        (:func:`pose_u` of the source frames), increasing.
    rotation_noise : ndarray, shape (M, J, 3), optional
        The noise layer (module notes): rotation vectors applied last,
        ``mul(v, exp(n))``.  ``None`` (with ``noise_u``): no noise layer.
    rotation_sharp : ndarray, shape (N, J, 3), optional
        The sharp layer (module notes): rotation vectors sampled at
        ``sample_u`` like the displacement maps, applied after them.
        ``None``: no sharp layer.

    Examples
    --------
    >>> import numpy as np
    >>> import mocaplab as ml
    >>> clip = ml.cmu("16_15").resample(30)[:60]
    >>> sm = ml.staggered.extract(clip)
    >>> sm.n_poses, sm.refinements.shape                # K poses, V = J + 1 variables
    (6, (6, 32))
    >>> bool(np.allclose(sm.evaluate().global_positions(), clip.global_positions()))
    True
    """

    skeleton: Skeleton
    fps: float
    times: Array
    refinements: Array
    root_values: Array
    rotation_values: Array
    root_tangents: Array
    rotation_tangents: Array
    sample_u: Array
    root_displacement: Array
    rotation_displacement: Array
    active: NDArray[np.bool_] = None  # type: ignore[assignment]  # None: every pose controls every variable
    priorities: Array = None  # type: ignore[assignment]  # None: NaN
    name: str = ""
    constraints: Any = None
    translation_joints: tuple[int, ...] = ()
    translation_values: Array = None  # type: ignore[assignment]  # None: no translation variables
    translation_tangents: Array = None  # type: ignore[assignment]
    translation_displacement: Array = None  # type: ignore[assignment]
    rest_translations: Array | None = None
    noise_u: Array | None = None
    rotation_noise: Array | None = None
    rotation_sharp: Array | None = None

    def __post_init__(self) -> None:
        J = self.skeleton.n_joints
        tj = tuple(int(j) for j in self.translation_joints)
        if any(not 0 < j < J for j in tj) or len(set(tj)) != len(tj):
            raise ValueError(f"Expected `translation_joints` to be distinct joint indices in [1, {J}), got {tj}")
        T = len(tj)
        V = J + 1 + T
        times = np.array(self.times, dtype=float).reshape(-1)
        K = times.size
        if K < 2:
            raise ValueError(f"Expected at least 2 poses in `times`, got {K}")
        if not np.all(np.diff(times) > 0):
            raise ValueError(f"Expected strictly increasing pose `times`, got {times}")

        def arr(x: Any, shape: tuple[int, ...], label: str, dtype: Any = float) -> NDArray[Any]:
            if x is None and 0 in shape:
                x = np.zeros(shape, dtype=dtype)
            a = np.array(x, dtype=dtype, copy=True)
            if a.shape != shape:
                raise ValueError(f"Expected `{label}` of shape {shape}, got {a.shape}")
            if dtype is float and not np.all(np.isfinite(a)):
                raise ValueError(f"Expected finite `{label}`, got NaN or inf")
            return readonly(a)

        object.__setattr__(self, "translation_joints", tj)
        refinements = arr(self.refinements, (K, V), "refinements")
        active = arr(np.ones((K, V), bool) if self.active is None else self.active, (K, V), "active", bool)
        if not (active[0].all() and active[-1].all()):
            raise ValueError("Expected the first and last poses to control every variable (`active` rows 0 and -1)")
        knots = np.where(active, times[:, None] + refinements, np.nan)
        for i in range(V):
            col = knots[active[:, i], i]
            if not np.all(np.diff(col) > 0):
                bad = int(np.flatnonzero(np.diff(col) <= 0)[0])
                raise ValueError(
                    f"Refined knot times of variable {self.variables[i]!r} are out of order "
                    f"(knot {bad} at {col[bad]:.4f} s, next at {col[bad + 1]:.4f} s): reduce the timing edit"
                )
        N = np.asarray(self.sample_u).shape[0]
        object.__setattr__(self, "fps", float(self.fps))
        times = readonly(times)
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "refinements", refinements)
        object.__setattr__(self, "active", active)
        object.__setattr__(self, "root_values", arr(self.root_values, (K, 3), "root_values"))
        rv = arr(self.rotation_values, (K, J, 4), "rotation_values")
        object.__setattr__(self, "rotation_values", rv)
        object.__setattr__(self, "root_tangents", arr(self.root_tangents, (K, 2, 3), "root_tangents"))
        object.__setattr__(self, "rotation_tangents", arr(self.rotation_tangents, (K, J, 2, 4), "rotation_tangents"))
        object.__setattr__(self, "sample_u", arr(self.sample_u, (N, V), "sample_u"))
        object.__setattr__(self, "root_displacement", arr(self.root_displacement, (N, 3), "root_displacement"))
        object.__setattr__(
            self, "rotation_displacement", arr(self.rotation_displacement, (N, J, 3), "rotation_displacement")
        )
        object.__setattr__(self, "translation_values", arr(self.translation_values, (K, T, 3), "translation_values"))
        object.__setattr__(
            self, "translation_tangents", arr(self.translation_tangents, (K, T, 2, 3), "translation_tangents")
        )
        object.__setattr__(
            self,
            "translation_displacement",
            arr(self.translation_displacement, (N, T, 3), "translation_displacement"),
        )
        if self.rest_translations is None:
            if T:
                raise ValueError(
                    "Expected `rest_translations` of shape (J, 3) with translation variables "
                    f"(`translation_joints` {tj}), got None"
                )
        else:
            object.__setattr__(self, "rest_translations", arr(self.rest_translations, (J, 3), "rest_translations"))
        if (self.noise_u is None) != (self.rotation_noise is None):
            raise ValueError("Expected both `noise_u` and `rotation_noise`, or neither")
        if self.noise_u is not None:
            nu = np.asarray(self.noise_u, dtype=float).reshape(-1)
            M = nu.size
            if M < 1 or not np.all(np.diff(nu) > 0):
                raise ValueError(f"Expected increasing `noise_u` (pose-index units), got {M} values")
            object.__setattr__(self, "noise_u", arr(nu, (M,), "noise_u"))
            object.__setattr__(self, "rotation_noise", arr(self.rotation_noise, (M, J, 3), "rotation_noise"))
        if self.rotation_sharp is not None:
            object.__setattr__(self, "rotation_sharp", arr(self.rotation_sharp, (N, J, 3), "rotation_sharp"))
        pr = np.full(K, np.nan) if self.priorities is None else np.array(self.priorities, dtype=float, copy=True)
        if pr.shape != (K,):
            raise ValueError(f"Expected `priorities` of shape ({K},), got {pr.shape}")
        object.__setattr__(self, "priorities", readonly(pr))
        object.__setattr__(self, "name", str(self.name))

    # ----------------------------------------------------------------- sizes
    @property
    def n_poses(self) -> int:
        """Number of staggered poses ``K``."""
        return int(self.times.size)

    @property
    def n_joints(self) -> int:
        return self.skeleton.n_joints

    @property
    def n_translations(self) -> int:
        """Number of translation variables ``T``."""
        return len(self.translation_joints)

    @property
    def n_variables(self) -> int:
        """Number of control variables ``V = J + 1 + T``."""
        return self.skeleton.n_joints + 1 + len(self.translation_joints)

    @property
    def variables(self) -> tuple[str, ...]:
        """Control variable names (see the module docstring)."""
        return variable_names(self.skeleton, self.translation_joints)

    @property
    def position_columns(self) -> NDArray[np.int64]:
        """Variable indices of the position variables, shape (P,): ``[0, J + 1, ..., J + T]``."""
        J = self.n_joints
        return np.concatenate([[0], J + 1 + np.arange(self.n_translations)]).astype(np.int64)

    @property
    def position_values(self) -> Array:
        """Extreme values of the position variables, shape (K, P, 3): root first, then the translations."""
        return np.concatenate([self.root_values[:, None], self.translation_values], axis=1)

    def is_translation(self, i: int) -> bool:
        """Whether variable ``i`` is a position (root or joint translation) rather than a rotation."""
        return not 1 <= int(i) <= self.n_joints

    @property
    def duration(self) -> float:
        """Seconds from 0 to the last pose."""
        return float(self.times[-1])

    @property
    def n_frames(self) -> int:
        """Frames produced by :meth:`evaluate` at ``fps``."""
        return int(_frame_times(self.duration, self.fps).size)

    @property
    def knot_times(self) -> Array:
        """Refined knot times ``t_k + r_{k,i}``, shape (K, V) (NaN where inactive)."""
        return np.where(self.active, self.times[:, None] + self.refinements, np.nan)

    @property
    def editing_knots(self) -> NDArray[np.bool_]:
        """Where an editing knot exists (active and ``r_{k,i} != 0``), shape (K, V)."""
        return self.active & (self.refinements != 0.0)

    def variable_index(self, name: str) -> int:
        """Index of a control variable by name (a joint name, ``"root_position"`` or ``"<joint>.position"``)."""
        names = self.variables
        if name not in names:
            raise KeyError(f"No control variable {name!r}; variables are {list(names)}")
        return names.index(name)

    def __repr__(self) -> str:
        label = f" {self.name!r}" if self.name else ""
        return (
            f"<StaggeredMotion{label}: {self.n_poses} poses over {self.duration:.2f} s, "
            f"{self.n_variables} variables, {int(self.editing_knots.sum())} refined knots>"
        )

    # ------------------------------------------------------------ evaluation
    def locate(self, t: ArrayLike, *, staggered: bool = True) -> tuple[NDArray[np.int64], NDArray[np.int64], Array]:
        """Segment and normalised time of every variable at times ``t``.

        Parameters
        ----------
        t : array_like, shape (F,)
            Times in seconds.
        staggered : bool
            False evaluates the non-staggered motion (all refinements zero).

        Returns
        -------
        k0, k1 : ndarray of int, shape (F, V)
            Poses bounding the segment of each variable (consecutive active
            knots).
        tn : ndarray, shape (F, V)
            Normalised time ``t'`` in ``[0, 1]`` (held outside the knots).
        """
        return locate(self.times, self.refinements, self.active, t, staggered=staggered)

    def spline_values(
        self, k0: NDArray[np.int64], k1: NDArray[np.int64], tn: Array, *, with_translations: bool = False
    ) -> Any:
        """The spline layer ``s_i(t')`` at given segments and normalised times.

        ``k0, k1, tn`` have shape (..., V) as returned by :meth:`locate`.
        Returns root positions (..., 3) and rotations (..., J, 4), and with
        ``with_translations`` the translation variables (..., T, 3) too.
        """
        pos, rot = self._spline_layers(k0, tn)
        if with_translations:
            return pos[..., 0, :], rot, pos[..., 1:, :]
        return pos[..., 0, :], rot

    def _spline_layers(self, k0: NDArray[np.int64], tn: Array) -> tuple[Array, Array]:
        """Spline layer of every variable: positions (..., P, 3), rotations (..., J, 4)."""
        return _spline(self.control_points_all(), self.position_columns, k0, tn)

    def control_points(self) -> tuple[Array, Array, Array]:
        """Absolute spline control points, indexed by the segment's start pose (cached).

        Returns root controls (K, 4, 3) ``P0..P3``, rotation controls
        (K, J, 4, 4) ``q1..q4`` and the angles between consecutive rotation
        controls (K, J, 3).  :meth:`control_points_all` has the translation
        variables' controls too.
        """
        pos_c, rot_c, rot_th = self.control_points_all()
        return pos_c[:, 0], rot_c, rot_th

    def control_points_all(self) -> tuple[Array, Array, Array]:
        """As :meth:`control_points`, with position controls (K, P, 4, 3) for every position variable (cached)."""
        ctrl = self.__dict__.get("_ctrl")
        if ctrl is None:
            ctrl = _controls(
                self.position_values,
                np.concatenate([self.root_tangents[:, None], self.translation_tangents], axis=1),
                self.rotation_values,
                self.rotation_tangents,
                self.active,
                self.position_columns,
            )
            object.__setattr__(self, "_ctrl", ctrl)
        return ctrl

    def displacement_values(self, u: NDArray[Any], *, with_translations: bool = False) -> Any:
        """The displacement layer at positions ``u`` (shape (F, V)).

        Returns translations (F, 3) and rotation vectors (F, J, 3), and with
        ``with_translations`` the translation variables' displacements
        (F, T, 3) too.
        """
        pos, rot = self._displacement_layers(u)
        if with_translations:
            return pos[:, 0], rot, pos[:, 1:]
        return pos[:, 0], rot

    def _displacement_layers(self, u: NDArray[Any]) -> tuple[Array, Array]:
        """Displacements of every variable at ``u`` (F, V): positions (F, P, 3), rotation vectors (F, J, 3)."""
        pc = self.position_columns
        J = self.n_joints
        pos = _interp_block(self.sample_u[:, pc], self.position_displacement, u[:, pc])
        rot = _interp_block(self.sample_u[:, 1 : J + 1], self.rotation_displacement, u[:, 1 : J + 1])
        return pos, rot

    @property
    def position_displacement(self) -> Array:
        """Displacements of the position variables, shape (N, P, 3): root first."""
        return np.concatenate([self.root_displacement[:, None], self.translation_displacement], axis=1)

    @cached_property
    def motion(self) -> Motion:
        """The motion this representation stands for: :meth:`evaluate` with its defaults, computed once.

        As every result in mocaplab gives its output (``EditResult.motions``,
        ``TouchUpHistory.motion``), an edited ``StaggeredMotion`` gives its
        motion as ``.motion``; :meth:`evaluate` takes other times or layers.
        """
        return self.evaluate()

    def evaluate(
        self,
        times: ArrayLike | None = None,
        *,
        staggered: bool = True,
        constraints: bool = True,
        noise: bool = True,
    ) -> Motion:
        """Evaluate the representation into a dense Motion.

        Parameters
        ----------
        times : array_like, shape (F,), optional
            Times in seconds; default every frame ``i / fps`` from 0 to the
            last pose time.
        staggered : bool
            False gives the non-staggered motion: every refinement treated as
            zero (the splines and displacement maps are warped with the knots).
        constraints : bool
            Apply the contact constraint layer if this object has one.
        noise : bool
            Apply the sharp and noise layers if this object has them (False
            gives the filtered motion the splines and displacement maps carry).

        Returns
        -------
        Motion
            At ``fps``.  Rotations are ``s (+) d (+) h (+) n``, ``mul(s, exp(d), exp(h), exp(n))``,
            the root position and the translation variables ``s + d``; the
            motion has ``translations`` (F, J, 3) when the source clip had them.
        """
        default = times is None and noise
        if default and staggered and constraints and "_dense" in self.__dict__:
            return self.__dict__["_dense"]
        t = _frame_times(self.duration, self.fps) if times is None else np.asarray(times, dtype=float).reshape(-1)
        if default and staggered:
            pos, rot = self._raw()
        else:
            pos, rot = self._compose(t, staggered=staggered, noise=noise)
        motion = Motion(
            self.skeleton, rot, pos[:, 0], self.fps, translations=self._translations(pos[:, 1:]), name=self.name
        )
        if constraints and self.constraints is not None:
            motion = self.constraints.apply(self, motion, t, staggered=staggered)
        if default and staggered and constraints:
            object.__setattr__(self, "_dense", motion)
        return motion

    def _translations(self, values: Array) -> Array | None:
        """Local translations of every joint, (F, J, 3), from the translation variables' values (F, T, 3)."""
        if self.rest_translations is None:
            return None
        out = np.empty((values.shape[0], self.n_joints, 3))
        out[:] = self.rest_translations
        if self.translation_joints:
            out[:, list(self.translation_joints)] = values
        return out

    def _raw(self) -> tuple[Array, Array]:
        """Dense staggered composition on the default frames, before constraints (cached).

        Positions (F, P, 3) and rotations (F, J, 4).  An edit that changed
        only some variables hands its result the parent's dense arrays and
        the changed-variable mask (``_parent_raw``); only those columns are
        recomputed here.
        """
        raw = self.__dict__.get("_raw_cache")
        if raw is not None:
            return raw
        t = _frame_times(self.duration, self.fps)
        parent = self.__dict__.get("_parent_raw")
        if parent is not None and parent[0].shape[0] == t.size:
            p_pos, p_rot, changed = parent
            pos, rot = np.array(p_pos, copy=True), np.array(p_rot, copy=True)
            moving = np.ones(self.n_variables, dtype=bool)
            moving[1 : self.n_joints + 1] = ~self.static_joints()
            cols = np.flatnonzero(changed & moving)
            if cols.size:
                c_pos, ps, c_rot, js = self._compose_columns(t, cols, staggered=True)
                pos[:, ps] = c_pos
                rot[:, js] = c_rot
        else:
            pos, rot = self._compose(t)
        pos, rot = readonly(pos), readonly(rot)
        object.__setattr__(self, "_raw_cache", (pos, rot))
        self.__dict__.pop("_parent_raw", None)
        return pos, rot

    def _inherit_raw(self, parent: StaggeredMotion, changed: ArrayLike) -> None:
        """Let this (edited) object reuse ``parent``'s dense evaluation outside ``changed`` (V,)."""
        if "_raw_cache" in parent.__dict__:
            pos, rot = parent.__dict__["_raw_cache"]
            object.__setattr__(self, "_parent_raw", (pos, rot, np.asarray(changed, dtype=bool)))
        elif "_parent_raw" in parent.__dict__:
            pos, rot, prev = parent.__dict__["_parent_raw"]
            object.__setattr__(self, "_parent_raw", (pos, rot, prev | np.asarray(changed, dtype=bool)))

    def _compose(self, t: Array, *, staggered: bool = True, noise: bool = True) -> tuple[Array, Array]:
        """Every variable at times ``t`` (F,): positions (F, P, 3), rotations (F, J, 4).

        ``noise=False`` leaves out the noise layer.
        """
        static = self.static_joints()
        if static.any():
            # joints that never move (CMU hip joints, shoulders...) are their value
            J = self.n_joints
            cols = np.concatenate([self.position_columns, 1 + np.flatnonzero(~static)])
            pos, _, moving, js = self._compose_columns(t, cols, staggered=staggered, noise=noise)
            rot = np.empty((t.size, J, 4))
            rot[:] = self.rotation_values[0]
            rot[:, js] = moving
            return pos, rot
        k0, k1, tn = self.locate(t, staggered=staggered)
        s_pos, s_rot = self._spline_layers(k0, tn)
        u = k0 + tn * (k1 - k0)
        d_pos, d_rot = self._displacement_layers(u)
        rot = quat.mul(s_rot, quat.exp(d_rot))
        if noise:
            js = np.arange(self.n_joints)
            rot = self._add_noise(self._add_sharp(rot, u[:, 1 : self.n_joints + 1], js), t, js)
        return s_pos + d_pos, rot

    def noise_values(self, t: ArrayLike, joints: ArrayLike | None = None) -> Array:
        """The noise layer at times ``t`` (F,): rotation vectors (F, j, 3) (zeros without one).

        Interpolated linearly between samples, exact on them; ``joints``
        selects columns (default all).
        """
        t = np.asarray(t, dtype=float).reshape(-1)
        js = np.arange(self.n_joints) if joints is None else np.asarray(joints, dtype=np.int64)
        if self.rotation_noise is None or self.noise_u is None:
            return np.zeros((t.size, js.size, 3))
        u = pose_u(self.times, t)
        nu = self.noise_u
        f = self.rotation_noise[:, js]
        if nu.size == 1:
            return np.broadcast_to(f[0], (t.size,) + f.shape[1:]).copy()
        lo = np.clip(np.searchsorted(nu, u, side="right") - 1, 0, nu.size - 2)
        w = np.clip((u - nu[lo]) / (nu[lo + 1] - nu[lo]), 0.0, 1.0)  # exactly 0 on a sample
        g0 = f[lo]
        return g0 + w[:, None, None] * (f[lo + 1] - g0)

    def sharp_values(self, u: NDArray[Any], joints: ArrayLike | None = None) -> Array:
        """The sharp layer at positions ``u`` (F, j), the joints' own columns of :meth:`locate`'s ``k0 + t' (k1 - k0)``.

        Rotation vectors (F, j, 3), interpolated linearly between samples as
        the displacement maps (zeros without a sharp layer); ``joints``
        selects columns (default all).
        """
        js = np.arange(self.n_joints) if joints is None else np.asarray(joints, dtype=np.int64)
        u = np.asarray(u, dtype=float)
        if self.rotation_sharp is None:
            return np.zeros((u.shape[0], js.size, 3))
        return _interp_block(self.sample_u[:, 1 + js], self.rotation_sharp[:, js], u)

    def _add_sharp(self, rot: Array, u: NDArray[Any], js: NDArray[np.int64]) -> Array:
        """``rot (+) exp(h)`` for the joints ``js`` at their positions ``u`` (F, len(js))."""
        if self.rotation_sharp is None or js.size == 0:
            return rot
        return quat.mul(rot, quat.exp(self.sharp_values(u, js)))

    def _add_noise(self, rot: Array, t: Array, js: NDArray[np.int64]) -> Array:
        """``rot (+) exp(n)`` for the joints ``js`` (rot has shape (F, len(js), 4))."""
        if self.rotation_noise is None or js.size == 0:
            return rot
        return quat.mul(rot, quat.exp(self.noise_values(t, js)))

    def static_joints(self) -> NDArray[np.bool_]:
        """Joints whose rotation is constant everywhere, shape (J,) (cached).

        All knot values equal, tangents the identity and displacements below
        1e-15 rad: evaluating them gives their value, so they are skipped.
        """
        st = self.__dict__.get("_static")
        if st is None:
            v = self.rotation_values
            same = np.all(v == v[:1], axis=(0, 2))
            ident = np.all(np.abs(self.rotation_tangents[..., :3]) < 1e-15, axis=(0, 2, 3))
            still = np.all(np.abs(self.rotation_displacement) < 1e-15, axis=(0, 2))
            if self.rotation_noise is not None:
                still &= np.all(self.rotation_noise == 0.0, axis=(0, 2))
            if self.rotation_sharp is not None:
                still &= np.all(self.rotation_sharp == 0.0, axis=(0, 2))
            st = same & ident & still
            st = readonly(st)
            object.__setattr__(self, "_static", st)
        return st

    def _compose_columns(
        self, t: Array, cols: NDArray[np.int64], *, staggered: bool = True, noise: bool = True
    ) -> tuple[Array, NDArray[np.int64], Array, NDArray[np.int64]]:
        """Composition of a subset of variables at times ``t`` (the sharp and noise layers unless ``noise=False``).

        Returns positions (F, p, 3) with their indices into the position
        block (p,), rotations (F, r, 4) and their joint indices (r,).
        """
        J = self.n_joints
        cols = np.asarray(cols, dtype=np.int64)
        k0, k1, tn = locate(self.times, self.refinements, self.active, t, staggered=staggered, columns=cols)
        u = k0 + tn * (k1 - k0)
        pos_c, rot_c, rot_th = self.control_points_all()
        is_rot = (cols >= 1) & (cols <= J)
        pc = np.flatnonzero(~is_rot)
        # position-block index of each position column: 0 for the root, 1 + m for translation m
        ps = np.where(cols[pc] == 0, 0, cols[pc] - J)
        P = pos_c[k0[:, pc], ps]  # (F, p, 4, 3)
        s_pos = bezier(P[..., 0, :], P[..., 1, :], P[..., 2, :], P[..., 3, :], tn[:, pc])
        d_pos = _interp_block(self.sample_u[:, cols[pc]], self.position_displacement[:, ps], u[:, pc])
        rc = np.flatnonzero(is_rot)
        js = cols[rc] - 1
        kk = k0[:, rc]
        s_rot = casteljau(rot_c[kk, js], rot_th[kk, js], tn[:, rc])
        d_rot = _interp_block(self.sample_u[:, cols[rc]], self.rotation_displacement[:, js], u[:, rc])
        rot = quat.mul(s_rot, quat.exp(d_rot))
        if noise:
            rot = self._add_noise(self._add_sharp(rot, u[:, rc], js), t, js)
        return s_pos + d_pos, ps, rot, js

    def _pose(self, k: int, which: str) -> tuple[Array, Array]:
        """Pose ``k`` (true or non-staggered): positions (P, 3), rotations (J, 4)."""
        if which not in ("true", "non-staggered"):
            raise ValueError(f"Expected `which` in ('true', 'non-staggered'), got {which!r}")
        k = self._pose_index(k)
        pos, rot = self._compose(np.array([self.times[k]]))
        pos, rot = pos[0], rot[0]
        if which == "true":
            return pos, rot
        act = self.active[k]
        pos = np.where(act[self.position_columns, None], self.position_values[k], pos)
        rot = np.where(act[1 : self.n_joints + 1, None], self.rotation_values[k], rot)
        return pos, rot

    def true_pose(self, k: int) -> tuple[Array, Array]:
        """The pose at the staggered pose time ``t_k``: root (3,), rotations (J, 4).

        (:meth:`pose_motion` has the translation variables too.)
        """
        pos, rot = self._pose(k, "true")
        return pos[0], rot

    def non_staggered_pose(self, k: int) -> tuple[Array, Array]:
        """The non-staggered pose: every variable at its extreme value ``v_{k,i}``.

        Variables the pose does not control (partial poses) take their true
        value at ``t_k``.  Returns root (3,), rotations (J, 4).
        """
        pos, rot = self._pose(k, "non-staggered")
        return pos[0], rot

    def pose_motion(self, k: int, *, which: Literal["true", "non-staggered"] = "true") -> Motion:
        """A one-frame Motion of pose ``k`` (``which``: true or non-staggered pose), translations included."""
        pos, rot = self._pose(k, which)
        return Motion(
            self.skeleton,
            rot[None],
            pos[None, 0],
            self.fps,
            translations=self._translations(pos[None, 1:]),
            name=f"{self.name} pose {k} ({which})",
        )

    def editing_knot_values(self) -> tuple[Array, Array]:
        """Values of all editing knots (true values at ``t_k``): root (K, 3), rotations (K, J, 4).

        Entries where :attr:`editing_knots` is False equal the extreme values.
        """
        pos, rot = self._compose(self.times)
        ek = self.editing_knots
        root = np.where(ek[:, :1], pos[:, 0], self.root_values)
        rot = np.where(ek[:, 1 : self.n_joints + 1, None], rot, self.rotation_values)
        return root, rot

    def _pose_index(self, k: int) -> int:
        if not isinstance(k, (int, np.integer)) or not -self.n_poses <= k < self.n_poses:
            raise IndexError(f"Expected a pose index in [0, {self.n_poses}), got {k!r}")
        return int(k) % self.n_poses

    # ------------------------------------------------------------- warnings
    def timing_conflicts(self) -> NDArray[np.bool_]:
        """Knots closer to a neighbouring pose than to their own, shape (K, V) (section 5.2)."""
        T = self.times[:, None] + self.refinements
        own = np.abs(self.refinements)
        prev = np.full_like(T, np.inf)
        nxt = np.full_like(T, np.inf)
        prev[1:] = np.abs(T[1:] - self.times[:-1, None])
        nxt[:-1] = np.abs(T[:-1] - self.times[1:, None])
        return self.active & ((prev < own) | (nxt < own))

    def _warn_timing(self) -> None:
        bad = self.timing_conflicts()
        if bad.any():
            k, i = np.argwhere(bad)[0]
            warn(
                f"{int(bad.sum())} refined knot(s) are closer to a neighbouring pose than to their own, e.g. "
                f"{self.variables[i]!r} of pose {k} at {self.times[k] + self.refinements[k, i]:.3f} s",
                StaggeredTimingWarning,
            )

    # ----------------------------------------------------------- refinements
    def with_refinements(self, refinements: ArrayLike) -> StaggeredMotion:
        """A copy with new timing refinements (shape (K, V)); see :func:`set_refinements`."""
        return set_refinements(self, refinements)

    def zero_refinements(self) -> StaggeredMotion:
        """The non-staggered representation: all refinements set to zero."""
        return set_refinements(self, np.zeros_like(self.refinements))

    # the section 5 edits are functions of mocaplab.staggered.edit, not methods (that module sits above this one)
    retime = Gone("the section 5 edits are functions, write mocaplab.staggered.retime(sm, ...)")
    succession = Gone("the section 5 edits are functions, write mocaplab.staggered.succession(sm, ...)")
    randomize = Gone("the section 5 edits are functions, write mocaplab.staggered.randomize(sm, ...)")
    edit_pose = Gone("the section 5 edits are functions, write mocaplab.staggered.edit_pose(sm, ...)")
    exaggerate = Gone("the section 5 edits are functions, write mocaplab.staggered.exaggerate(sm, ...)")
    insert_pose = Gone("the section 5 edits are functions, write mocaplab.staggered.insert_pose(sm, ...)")
    delete_pose = Gone("the section 5 edits are functions, write mocaplab.staggered.delete_pose(sm, ...)")


def set_refinements(sm: StaggeredMotion, refinements: ArrayLike) -> StaggeredMotion:
    """A copy with new refinements, shape (K, V) seconds.

    The one place refinements change (every timing edit of
    :mod:`~mocaplab.staggered.edit` ends here): the knot values, tangents and
    displacement maps are unchanged by retiming, so their caches are kept.

    Parameters
    ----------
    sm : StaggeredMotion
    refinements : array_like, shape (K, V)
        Timing refinements ``r_{k,i}`` in seconds; entries of variables a pose
        does not control (``sm.active`` False) are set to 0.

    Returns
    -------
    StaggeredMotion
        ``sm`` itself when nothing changes, else a new object.

    Raises
    ------
    ValueError
        If ``refinements`` has another shape, or a variable's refined knots would cross.

    Warns
    -----
    StaggeredTimingWarning
        When a knot is closer to a neighbouring pose than to its own.

    Examples
    --------
    >>> import mocaplab as ml
    >>> sm = ml.staggered.extract(ml.cmu("16_15").resample(30)[:60])
    >>> r = sm.refinements.copy()
    >>> r[2, 0] = 0.05                      # pose 2's root translation 50 ms late
    >>> float(ml.staggered.set_refinements(sm, r).refinements[2, 0])
    0.05
    >>> r[2, 0] = 5.0                       # past the next pose
    >>> ml.staggered.set_refinements(sm, r)
    Traceback (most recent call last):
    ...
    ValueError: Refined knot times of variable 'root_position' are out of order ...
    """
    r = np.asarray(refinements, dtype=float)
    if r.shape != sm.refinements.shape:
        raise ValueError(f"Expected `refinements` of shape {sm.refinements.shape}, got {r.shape}")
    if np.array_equal(r, sm.refinements):
        return sm
    out = dataclasses.replace(sm, refinements=np.where(sm.active, r, 0.0))
    for cached in ("_ctrl", "_static"):  # values, tangents and displacements are unchanged by retiming
        if cached in sm.__dict__:
            object.__setattr__(out, cached, sm.__dict__[cached])
    out._inherit_raw(sm, np.any(r != sm.refinements, axis=0))
    out._warn_timing()
    return out


# ------------------------------------------------------------------ helpers
def locate(
    times: Array,
    refinements: Array,
    active: NDArray[np.bool_],
    t: ArrayLike,
    *,
    staggered: bool = True,
    columns: ArrayLike | None = None,
) -> tuple[NDArray[np.int64], NDArray[np.int64], Array]:
    """Segment (bounding active poses ``k0, k1``) and normalised time of every variable.

    ``times`` (K,), ``refinements`` and ``active`` (K, V), ``t`` (F,) or
    (F, V) (one time column per variable); returns ``k0, k1`` (F, V) int and
    ``t'`` (F, V) clipped to [0, 1] (only the variables ``columns`` if
    given).  A time exactly on a knot belongs to the segment that starts
    there.
    """
    t = np.asarray(t, dtype=float)
    K, V = refinements.shape
    cols = np.arange(V) if columns is None else np.asarray(columns, dtype=np.int64)
    F = t.shape[0]
    knots = times[:, None] + (refinements if staggered else np.zeros_like(refinements))
    n = cols.size
    k0 = np.empty((F, n), dtype=np.int64)
    k1 = np.empty((F, n), dtype=np.int64)
    tn = np.empty((F, n))
    full = bool(active.all())
    all_idx = np.arange(K)
    if full and K >= 2:
        Tc = knots[:, cols]
        s = _search_columns(Tc, t if t.ndim == 1 else t[:, cols]) - 1
        np.clip(s, 0, K - 2, out=s)
        c_idx = np.arange(n)
        a, b = Tc[s, c_idx], Tc[s + 1, c_idx]
        tc = t[:, None] if t.ndim == 1 else t[:, cols]
        x = (tc - a) / (b - a)
        np.clip(x, 0.0, 1.0, out=x)
        return s, s + 1, x
    for c, i in enumerate(cols):
        idx = all_idx if full else np.flatnonzero(active[:, i])
        T = knots[idx, i]
        tc = t[:, i] if t.ndim == 2 else t
        s = np.searchsorted(T, tc, side="right") - 1
        np.clip(s, 0, idx.size - 2, out=s)
        a, b = T[s], T[s + 1]
        k0[:, c] = idx[s]
        k1[:, c] = idx[s + 1]
        x = (tc - a) / (b - a)
        np.clip(x, 0.0, 1.0, out=x)
        tn[:, c] = x
    return k0, k1, tn


def pose_u(times: Array, t: ArrayLike) -> NDArray[np.float64]:
    """Position of times ``t`` in pose-index units, ``k + (t - t_k) / (t_{k+1} - t_k)``, clamped to the poses.

    The pose timing shared by every variable (refinements ignored): the
    noise layer and the constraint layer follow it, so they move with
    retimed poses.  ``times`` (K,) increasing; returns the shape of ``t``.
    """
    t = np.asarray(t, dtype=float)
    k = np.clip(np.searchsorted(times, t, side="right") - 1, 0, times.size - 2)
    frac = np.clip((t - times[k]) / (times[k + 1] - times[k]), 0.0, 1.0)
    return np.asarray(k + frac, dtype=np.float64)


def pose_time(times: Array, u: ArrayLike) -> NDArray[np.float64]:
    """Inverse of :func:`pose_u`: seconds of positions ``u`` (pose-index units)."""
    u = np.asarray(u, dtype=float)
    k = np.clip(np.floor(u).astype(np.int64), 0, times.size - 2)
    return np.asarray(times[k] + (u - k) * (times[k + 1] - times[k]), dtype=np.float64)


def next_active(active: NDArray[np.bool_]) -> NDArray[np.int64]:
    """For each (k, i), the next pose after ``k`` controlling variable ``i`` (-1 if none), shape (K, V)."""
    K, V = active.shape
    out = np.full((K, V), -1, dtype=np.int64)
    nxt = np.full(V, -1, dtype=np.int64)
    for k in range(K - 1, -1, -1):
        out[k] = nxt
        nxt = np.where(active[k], k, nxt)
    return out


def _spline(
    controls: tuple[Array, Array, Array],
    position_columns: NDArray[np.int64],
    k0: NDArray[np.int64],
    tn: Array,
) -> tuple[Array, Array]:
    """Spline layer at (..., V) segment starts ``k0`` and normalised times ``tn``.

    ``controls`` as returned by :func:`_controls`; returns positions
    (..., P, 3) and rotations (..., J, 4).
    """
    pos_c, rot_c, rot_th = controls
    P = pos_c.shape[1]
    J = rot_c.shape[1]
    C = pos_c[k0[..., position_columns], np.arange(P)]  # (..., P, 4, 3)
    pos = bezier(C[..., 0, :], C[..., 1, :], C[..., 2, :], C[..., 3, :], tn[..., position_columns])
    j = np.arange(J)
    r0 = k0[..., 1 : J + 1]
    return pos, casteljau(rot_c[r0, j], rot_th[r0, j], tn[..., 1 : J + 1])


def _controls(
    position_values: Array,
    position_tangents: Array,
    rotation_values: Array,
    rotation_tangents: Array,
    active: NDArray[np.bool_] | None,
    position_columns: NDArray[np.int64] | None = None,
) -> tuple[Array, Array, Array]:
    """Absolute control points of every segment, indexed by its start pose.

    ``position_values`` (K, P, 3) and ``position_tangents`` (K, P, 2, 3) are
    the position variables (variable columns ``position_columns``, default
    ``[0]``), ``rotation_values`` (K, J, 4) and ``rotation_tangents``
    (K, J, 2, 4) the rotations (columns ``1 .. J``).  Returns position
    controls (K, P, 4, 3), rotation controls (K, J, 4, 4) and the angles
    between consecutive rotation controls (K, J, 3).
    """
    K, J = rotation_values.shape[:2]
    P = position_values.shape[1]
    pcols = np.zeros(1, dtype=np.int64) if position_columns is None else np.asarray(position_columns)
    if active is None:
        active = np.ones((K, J + P), dtype=bool)
    nxt = next_active(active)
    nxt = np.where(nxt < 0, np.arange(K)[:, None], nxt)
    p0 = position_values
    p3 = position_values[nxt[:, pcols], np.arange(P)]
    pos_c = np.stack([p0, p0 + position_tangents[:, :, 0], p3 + position_tangents[:, :, 1], p3], axis=2)
    j = np.arange(J)
    q1 = rotation_values
    q4 = rotation_values[nxt[:, 1 : J + 1], j]
    q2 = quat.mul(q1, rotation_tangents[:, :, 0])
    q3 = quat.mul(q4, rotation_tangents[:, :, 1])
    rot_c = np.stack([q1, q2, q3, q4], axis=2)
    dots = np.einsum("...i,...i->...", rot_c[:, :, :3], rot_c[:, :, 1:])
    return pos_c, rot_c, np.arccos(np.clip(dots, -1.0, 1.0))


def casteljau(ctrl: Array, theta: Array, t: Array) -> Array:
    """Recursive slerp of unit control quaternions (the evaluation kernel).

    The same curve as :func:`quat_bezier`, computed level by level with the
    slerps of a level stacked in one array operation, and with the first
    level's angles precomputed.

    Parameters
    ----------
    ctrl : ndarray, shape (..., 4, 4)
        Control quaternions ``q1 .. q4`` (unit, one hemisphere).
    theta : ndarray, shape (..., 3)
        Angles between consecutive controls (``arccos`` of their dots).
    t : ndarray, shape (...,)

    Returns
    -------
    ndarray, shape (..., 4)

    Notes
    -----
    Angles are floored at 1e-7 rad, where ``sin(x theta) / sin(theta)``
    equals ``x`` to 1e-14, which replaces the small-angle branch.
    """
    tt = np.asarray(t, dtype=float)[..., None]
    u = 1.0 - tt
    th = np.maximum(theta, 1e-7)
    inv = 1.0 / np.sin(th)
    lev = (np.sin(u * th) * inv)[..., None] * ctrl[..., :3, :] + (np.sin(tt * th) * inv)[..., None] * ctrl[..., 1:, :]
    for _ in range(2):
        a, b = lev[..., :-1, :], lev[..., 1:, :]
        th = np.maximum(np.arccos(np.clip(np.einsum("...i,...i->...", a, b), -1.0, 1.0)), 1e-7)
        inv = 1.0 / np.sin(th)
        lev = (np.sin(u * th) * inv)[..., None] * a + (np.sin(tt * th) * inv)[..., None] * b
    return lev[..., 0, :]


def _search_columns(sorted_cols: Array, queries: NDArray[Any]) -> NDArray[np.int64]:
    """``searchsorted(sorted_cols[:, c], queries[:, c], side="right")`` for every column at once.

    ``sorted_cols`` (N, V) increasing per column; ``queries`` (F, V) or (F,).
    The columns are laid end to end with offsets larger than their range,
    so one search serves all of them (order is kept by the monotone
    rounding of the offset sums; exact ties stay ties).
    """
    N, V = sorted_cols.shape
    lo = min(float(sorted_cols.min()), float(np.min(queries)))
    hi = max(float(sorted_cols.max()), float(np.max(queries)))
    step = (hi - lo) + 1.0
    off = (np.arange(V) * step) - lo
    flat = (sorted_cols + off).T.ravel()
    q = np.asarray(queries, dtype=float)
    q = (q[:, None] if q.ndim == 1 else q) + off
    # column-major queries are increasing runs: numpy's search reuses its last bounds
    pos = np.searchsorted(flat, q.T.ravel(), side="right").reshape(q.shape[::-1]).T
    return pos - np.arange(V) * N


def _interp_block(xp: Array, f: Array, u: NDArray[Any]) -> Array:
    """Per-variable linear interpolation of displacement samples.

    ``xp`` (N, n) increasing per column, ``f`` (N, n, D) the samples of each
    column, ``u`` (F, n); returns (F, n, D).  Exact on the samples: the
    weight of the next sample is exactly 0 there.
    """
    N, n = xp.shape
    F = u.shape[0]
    if n == 0:
        return np.zeros((F, 0) + f.shape[2:])
    if N == 1:
        lo = np.zeros((F, n), dtype=np.int64)
        w = np.zeros((F, n))
    else:
        lo = _search_columns(xp, u) - 1
        np.clip(lo, 0, N - 2, out=lo)
        cols = np.arange(n)
        x0 = xp[lo, cols]
        span = xp[lo + 1, cols] - x0
        ok = span > 0
        w = np.where(ok, (u - x0) / np.where(ok, span, 1.0), 0.0)
        np.clip(w, 0.0, 1.0, out=w)
    hi = np.minimum(lo + 1, N - 1)
    c = np.arange(n)
    g0 = f[lo, c]
    return g0 + w[..., None] * (f[hi, c] - g0)
