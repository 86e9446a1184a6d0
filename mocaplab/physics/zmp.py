"""Zero moment point and support polygon (Shin et al. 2003, section 3.1).

With the floor at ``y = 0`` and gravity ``g = (0, -9.81, 0)``, the ZMP of
point masses ``m_i`` at ``r_i`` with accelerations ``a_i`` is (equation 4)::

    Z_x = (sum m_i (a_iy - g_y) x_i - sum m_i (a_ix - g_x) y_i) / sum m_i (a_iy - g_y)
    Z_z = (sum m_i (a_iy - g_y) z_i - sum m_i (a_iz - g_z) y_i) / sum m_i (a_iy - g_y)

and ``Z_y = 0``.  Accelerations come from Gaussian-smoothed positions (the
paper's width of 5 frames at 30 fps, scaled to the clip's frame rate; see
:func:`mocaplab.physics.body.smoothed_derivatives`).

The **support polygon** of a frame is the convex hull of the ground
projections ``(x, z)`` of the support points of the planted joints (heel and
toe points of the feet, see :class:`~mocaplab.physics.body.Body`).  The
**signed distance** from the ZMP to it is positive outside, negative inside
and zero on the boundary; the paper's error ``f`` (equation 5, Figures 8
and 9) is its positive part.

Flight frames (no joint planted) have no ZMP: the denominator of equation 4
vanishes there.  They get NaN, and so do ground frames whose vertical
ground force would be negative (denominator at most 0.1 % of the weight),
without ever dividing by zero.

Speed note: :func:`support_polygon` builds one polygon with
:class:`scipy.spatial.ConvexHull` (for drawing and checks); distances over a
whole clip use :func:`polygon_distance`, an equivalent vectorised test on
the few support points of each frame (a pair of points is a hull edge when
all other points lie on one side of it), which is what keeps a touch-up
iteration in the millisecond range.  Tests check that both agree.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from functools import cached_property, lru_cache
from itertools import combinations, combinations_with_replacement
from typing import TYPE_CHECKING, Any, Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import ConvexHull, QhullError

from .. import quat
from ..contacts import resolve_contacts
from ..motion import Motion, _freeze, _owned, _take, readonly
from ..roles import resolve_roles
from .body import GRAVITY, Body, _positions_and_accelerations, paper_width

if TYPE_CHECKING:  # pragma: no cover
    from ..contacts import Contacts, Floor

__all__ = [
    "zmp_from_links",
    "support_polygon",
    "polygon_distance",
    "signed_distance",
    "Balance",
    "balance",
    "zmp_distance",
    "ground_contacts",
]

Array = NDArray[np.float64]
_EPS = 1e-10


# ------------------------------------------------------------------ equation 4
def zmp_from_links(
    positions: ArrayLike, accelerations: ArrayLike, masses: ArrayLike, *, gravity: ArrayLike = GRAVITY
) -> Array:
    """ZMP of point masses by equation 4, shape (F, 3) with ``y = 0``.

    Parameters
    ----------
    positions : array_like, shape (F, L, 3)
    accelerations : array_like, shape (F, L, 3)
    masses : array_like, shape (L,)
    gravity : array_like, shape (3,)

    Returns
    -------
    ndarray, shape (F, 3)
        NaN on frames whose denominator ``sum m_i (a_iy - g_y)`` is at most
        0.1 % of the weight (free fall or worse: no ground force to balance).

    Examples
    --------
    Two resting masses (no acceleration): the ZMP is below their centre of mass.

    >>> import numpy as np
    >>> from mocaplab.physics import zmp_from_links
    >>> positions = np.array([[[0.1, 1.0, 0.0], [0.3, 1.0, 0.0]]])     # one frame, two links
    >>> zmp_from_links(positions, np.zeros_like(positions), [1.0, 3.0]).round(6).tolist()
    [[0.25, 0.0, 0.0]]
    """
    r = np.asarray(positions, dtype=float)
    a = np.asarray(accelerations, dtype=float) - np.asarray(gravity, dtype=float)
    m = np.asarray(masses, dtype=float)
    if r.ndim != 3 or r.shape[-1] != 3 or a.shape != r.shape or m.shape != r.shape[1:2]:
        raise ValueError(
            f"Expected positions and accelerations of shape (F, L, 3) and masses (L,), "
            f"got {r.shape}, {a.shape} and {m.shape}"
        )
    zx, zz, ok = _zmp_xz(r, a, m, float(m.sum() * np.linalg.norm(gravity)))
    out = np.zeros((r.shape[0], 3))
    out[:, 0] = np.where(ok, zx, np.nan)
    out[:, 1] = np.where(ok, 0.0, np.nan)
    out[:, 2] = np.where(ok, zz, np.nan)
    return out


def _zmp_xz(r: Array, a: Array, m: Array, weight: float) -> tuple[Array, Array, NDArray[np.bool_]]:
    """Equation 4 on positions ``r`` and accelerations minus gravity ``a`` (F, L, 3).

    Returns ``Z_x``, ``Z_z`` (F,) and where the denominator exceeds 0.1 % of
    ``weight`` (elsewhere the values are meaningless, never a division by zero).
    """
    ma = a * m[:, None]  # (F, L, 3) mass-weighted
    den = ma[..., 1].sum(axis=1)
    ok = den > 1e-3 * weight
    safe = np.where(ok, den, 1.0)
    zx = (np.einsum("fl,fl->f", ma[..., 1], r[..., 0]) - np.einsum("fl,fl->f", ma[..., 0], r[..., 1])) / safe
    zz = (np.einsum("fl,fl->f", ma[..., 1], r[..., 2]) - np.einsum("fl,fl->f", ma[..., 2], r[..., 1])) / safe
    return zx, zz, ok


# ------------------------------------------------------------- support polygon
def support_polygon(points: ArrayLike) -> Array:
    """Convex hull of ground points (vertices counter-clockwise in ``(x, z)``).

    Parameters
    ----------
    points : array_like, shape (N, 2)
        Ground-plane coordinates ``(x, z)``.

    Returns
    -------
    ndarray, shape (V, 2)
        Hull vertices.  Degenerate cases: no points gives (0, 2); points that
        coincide give their single point; collinear points give the two
        extreme points (a segment).

    Examples
    --------
    An inner point is not a vertex:

    >>> import numpy as np
    >>> from mocaplab import physics
    >>> square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    >>> physics.support_polygon(np.r_[square, [[0.5, 0.5]]]).tolist()
    [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]
    """
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    if p.shape[0] == 0:
        return np.zeros((0, 2))
    p = np.unique(np.round(p, 12), axis=0)
    if p.shape[0] == 1:
        return p
    if p.shape[0] >= 3:
        try:
            hull = ConvexHull(p)
        except QhullError:
            pass  # collinear: fall through to the segment
        else:
            return p[hull.vertices]  # counter-clockwise in the (x, z) plane
    d = p - p.mean(axis=0)
    vt = np.linalg.svd(d, full_matrices=False)[2]
    t = d @ vt[0]
    return p[[int(np.argmin(t)), int(np.argmax(t))]]


def polygon_distance(
    points: ArrayLike, vertices: ArrayLike, active: ArrayLike | None = None, *, depth: bool = True
) -> tuple[Array, Array]:
    """Signed distance from points to the convex hulls of small point sets.

    Vectorised over frames: frame ``f`` measures ``points[f]`` against the
    convex hull of ``vertices[f, active[f]]``.

    Parameters
    ----------
    points : array_like, shape (F, 2)
        Query points (ZMPs) in ground coordinates ``(x, z)``; NaN allowed.
    vertices : array_like, shape (F, P, 2)
        Candidate hull points (support points) per frame.
    active : array_like of bool, shape (F, P), optional
        Which points exist on each frame (default: all).
    depth : bool
        Compute the (negative) depth of inside points; with False, inside
        points get 0, which is all the paper's error ``f`` needs, and is
        cheaper.

    Returns
    -------
    signed : ndarray, shape (F,)
        Positive outside, negative inside (minus the distance to the
        boundary), NaN where the query is NaN or no point is active.  A hull
        of one point or of collinear points has no inside.
    projection : ndarray, shape (F, 2)
        Nearest point of the hull (the query itself when inside).

    Examples
    --------
    One point a metre outside a unit square, one at its centre (half a metre deep):

    >>> import numpy as np
    >>> from mocaplab import physics
    >>> square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    >>> signed, nearest = physics.polygon_distance([[2.0, 0.5], [0.5, 0.5]], np.array([square, square]))
    >>> signed.tolist(), nearest.tolist()
    ([1.0, -0.5], [[1.0, 0.5], [0.5, 0.5]])
    """
    z = np.asarray(points, dtype=float)
    v = np.asarray(vertices, dtype=float)
    if z.ndim != 2 or z.shape[1] != 2 or v.ndim != 3 or v.shape[0] != z.shape[0] or v.shape[2] != 2:
        raise ValueError(f"Expected points (F, 2) and vertices (F, P, 2), got {z.shape} and {v.shape}")
    n_frames, n_pts = v.shape[:2]
    act = np.ones((n_frames, n_pts), dtype=bool) if active is None else np.asarray(active, dtype=bool)
    if act.shape != (n_frames, n_pts):
        raise ValueError(f"Expected `active` of shape ({n_frames}, {n_pts}), got {act.shape}")
    if n_pts == 0:
        return np.full(n_frames, np.nan), np.full((n_frames, 2), np.nan)
    finite = np.isfinite(z[:, 0]) & np.isfinite(z[:, 1])
    signed, px, pz = _polygon_xz(z[:, 0], z[:, 1], finite, v[..., 0], v[..., 1], act, depth)
    return signed, np.column_stack([px, pz])


def _polygon_xz(
    zx: Array,
    zz: Array,
    finite: NDArray[np.bool_],
    vx: Array,
    vz: Array,
    act: NDArray[np.bool_],
    depth: bool,
    segments: tuple[Array, ...] | None = None,
) -> tuple[Array, Array, Array]:
    """:func:`polygon_distance` on components: queries ``zx, zz`` (F,), points ``vx, vz`` (F, P).

    ``segments`` (from :func:`_segments` on the same points) saves their
    recomputation when the points are queried again.  Returns the signed
    distance and the projection's components, NaN where ``finite`` is False
    or no point is active.
    """
    n_frames, n_pts = act.shape
    rows = np.arange(n_frames)
    zx = np.where(finite, zx, 0.0)
    zz = np.where(finite, zz, 0.0)
    # points relative to the query, components apart: (F, P) each
    dx = vx - zx[:, None]
    dz = vz - zz[:, None]
    # nearest point over all segments between active points, a point being
    # the segment from itself to itself (pairs i <= j)
    i, j = _pairs(n_pts, True).T
    ex, ez, scale, penalty = _segments(vx, vz, act) if segments is None else segments
    ax, az = dx[:, i], dz[:, i]  # (F, K)
    # t = clip(-<a, e> / |e|^2, 0, 1), in place
    t = ax * ex
    t += az * ez
    t *= scale
    np.clip(t, 0.0, 1.0, out=t)
    qx, qz = ax + t * ex, az + t * ez  # nearest point of each segment, relative to the query
    d_seg = qx * qx
    d_seg += qz * qz
    d_seg += penalty  # +inf for pairs with an inactive point
    k = np.argmin(d_seg, axis=1)
    best_d = d_seg[rows, k]
    qx, qz = qx[rows, k], qz[rows, k]
    # inside test: outside a convex hull, every point p lies behind the line
    # through the nearest point q across z - q, <p - q, z - q> <= 0; inside
    # (z = sum_p l_p p, a convex combination, so that |z - q|^2 =
    # sum_p l_p <p - q, z - q>) some p lies in front of it.  (qx, qz) is
    # q - z.  A query on a segment (q = z) is on the boundary or inside: 0
    # either way, told apart by the depth below when it is asked for.
    ahead = np.where(act, (dx - qx[:, None]) * qx[:, None] + (dz - qz[:, None]) * qz[:, None], np.inf)
    dist = np.sqrt(best_d)
    inside = ahead.min(axis=1) < -1e-12 * dist
    signed = np.where(inside, 0.0, dist)
    n_act = act.sum(axis=1)
    if depth:
        inside |= (best_d == 0.0) & (n_act >= 3)
    if depth and np.any(inside):
        z0 = np.column_stack([zx, zz])
        v = np.stack([vx, vz], axis=-1)
        signed[inside] = -_depth(z0[inside], v[inside], act[inside], _pairs(n_pts))
    bad = ~finite | (n_act == 0)
    px = np.where(inside, zx, zx + qx)
    pz = np.where(inside, zz, zz + qz)
    signed[bad] = np.nan
    px[bad] = np.nan
    pz[bad] = np.nan
    return signed, px, pz


def _segments(vx: Array, vz: Array, act: NDArray[np.bool_]) -> tuple[Array, Array, Array, Array]:
    """The query-independent part of :func:`_polygon_xz`: segments between point pairs ``i <= j``.

    Returns their directions ``ex, ez``, ``-1 / |e|^2`` (0 for a point) and
    a penalty, 0 for segments between active points and infinite for the
    others, each (F, K).
    """
    i, j = _pairs(act.shape[1], True).T
    ex, ez = vx[:, j] - vx[:, i], vz[:, j] - vz[:, i]
    ee = ex * ex + ez * ez
    scale = -1.0 / np.where(ee > _EPS * _EPS, ee, np.inf)
    return ex, ez, scale, np.where(act[:, i] & act[:, j], 0.0, np.inf)


def _depth(z: Array, v: Array, act: NDArray[np.bool_], pairs: NDArray[np.int64]) -> Array:
    """Distance from inside points to the hull boundary, shape (F,).

    The depth is the minimum over unit directions ``u`` of ``h(u) - <z, u>``,
    ``h`` the support function; it is reached at a hull-edge normal, and
    every hull edge joins two support points, so the normals of all pairs
    suffice.
    """
    i, j = pairs[:, 0], pairs[:, 1]
    e = v[:, j] - v[:, i]
    ee = np.einsum("fkc,fkc->fk", e, e)
    ok = act[:, i] & act[:, j] & (ee > _EPS * _EPS)
    scale = 1.0 / np.sqrt(np.where(ok, ee, 1.0))
    nx, ny = -e[..., 1] * scale, e[..., 0] * scale  # (F, K)
    vt = np.moveaxis(v, 1, 0)  # (P, F, 2): reduce over the leading axis (fast)
    h = nx[None] * vt[..., 0, None] + ny[None] * vt[..., 1, None]  # (P, F, K)
    pen = np.where(act.T, 0.0, np.inf)[..., None]
    hmax = (h - pen).max(axis=0)
    hmin = (h + pen).min(axis=0)
    zn = nx * z[:, 0, None] + ny * z[:, 1, None]
    gap = np.where(ok, np.minimum(hmax - zn, zn - hmin), np.inf)
    return np.maximum(np.min(gap, axis=1), 0.0)


@lru_cache(maxsize=32)
def _pairs(n: int, with_self: bool = False) -> NDArray[np.int64]:
    """Index pairs ``i < j`` (``i <= j`` with ``with_self``) of ``n`` points, shape (K, 2)."""
    pick = combinations_with_replacement if with_self else combinations
    return readonly(np.array(list(pick(range(n), 2)), dtype=np.int64).reshape(-1, 2))


def signed_distance(point: ArrayLike, polygon: ArrayLike) -> float:
    """Signed distance from one ground point to one convex polygon (V, 2).

    Positive outside, negative inside; a polygon of fewer than three
    vertices (a point or a segment) has no inside.

    Parameters
    ----------
    point : array_like, shape (2,)
        Ground coordinates ``(x, z)``, metres.
    polygon : array_like, shape (V, 2)
        Convex polygon vertices (:func:`support_polygon`).

    Returns
    -------
    float
        Metres.

    Examples
    --------
    >>> import numpy as np
    >>> from mocaplab import physics
    >>> square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    >>> physics.signed_distance([2.0, 0.5], square), physics.signed_distance([0.5, 0.5], square)
    (1.0, -0.5)
    """
    p = np.asarray(point, dtype=float).reshape(1, 2)
    poly = np.asarray(polygon, dtype=float).reshape(1, -1, 2)
    s, _ = polygon_distance(p, poly)
    return float(s[0])


# --------------------------------------------------------------- per clip
def ground_contacts(
    contacts: Contacts | Literal["auto"] | None, motion: Motion, *, roles: Mapping[str, Any] | None = None
) -> Contacts:
    """The contacts a balance is measured on: ``contacts=`` read as everywhere (:func:`mocaplab.contacts.resolve_contacts`).

    ``"auto"`` detects the feet's contacts; ``None`` (no contacts) leaves no
    support polygon and no take-off or landing, so it raises ValueError.
    """
    found = resolve_contacts(contacts, motion, roles=roles)
    if found is None:
        raise ValueError(
            'contacts=None means no contacts: nothing stands on the ground to balance; give contacts="auto" '
            "(detected) or a mocaplab.contacts.Contacts"
        )
    return found


def _check_contacts(contacts: Contacts, motion: Motion) -> None:
    mask = getattr(contacts, "mask", None)
    if mask is None or not hasattr(contacts, "joints"):
        raise TypeError(f"Expected `contacts` to be a Contacts object, got {type(contacts).__name__}")
    if mask.shape[0] != motion.n_frames:
        raise ValueError(f"Expected `contacts` for {motion.n_frames} frames, got {mask.shape[0]}")


@dataclasses.dataclass(frozen=True, eq=False)
class Balance:
    """ZMP, support polygon and their distance on every frame of a clip.

    Parameters
    ----------
    zmp : ndarray, shape (F, 3)
        Equation 4 (``y = 0``); NaN on flight frames and on ground frames
        whose vertical ground force would be negative (see :attr:`dropped`).
    projection : ndarray, shape (F, 3)
        Nearest point of the support polygon to the ZMP (``y = 0``; the ZMP
        itself when inside).
    distance : ndarray, shape (F,)
        The paper's error ``f``: distance of the ZMP outside the support
        polygon, 0 inside, NaN where :attr:`zmp` is.
    com : ndarray, shape (F, 3)
        Centre of mass.
    ground : ndarray of bool, shape (F,)
        Frames with at least one planted joint.
    support : ndarray, shape (F, P, 3)
        Support points of the contact joints (heel and toe points).
    active : ndarray of bool, shape (F, P)
        Which support points are planted on each frame.
    positions, accelerations : ndarray, shape (F, L, 3)
        Smoothed link centres and their accelerations (what equation 4 used).

    Every array, :attr:`signed_distance` included, is read-only for good (a
    view of a read-only owner: ``flags.writeable = True`` raises); arrays
    given to the constructor are copied.

    Examples
    --------
    >>> import mocaplab as ml
    >>> b = ml.physics.balance(ml.cmu("16_15").resample(30)[:60])
    >>> b.zmp.shape, b.support.shape[0], int(b.ground.sum())
    ((60, 3), 60, 60)
    """

    zmp: Array
    projection: Array
    distance: Array
    com: Array
    ground: NDArray[np.bool_]
    support: Array
    active: NDArray[np.bool_]
    positions: Array
    accelerations: Array

    def __post_init__(self) -> None:
        # states of a touch-up history share Balance objects: every array is
        # read-only for good (a view of a read-only owner, motion.readonly);
        # arrays given from outside are copied first, those built here are
        # handed over with motion._owned
        for f in dataclasses.fields(self):
            arr, fresh = _take(getattr(self, f.name), bool if f.name in ("ground", "active") else float)
            object.__setattr__(self, f.name, _freeze(arr, fresh))

    @cached_property
    def signed_distance(self) -> Array:
        """Signed ZMP distance: positive outside, minus the depth inside, NaN in flight, shape (F,)."""
        ground = self.__dict__.get("_ground", _LEVEL)
        z, sup = ground.to_plane(self.zmp), ground.to_plane(self.support)
        signed, _ = polygon_distance(z[:, [0, 2]], sup[..., [0, 2]], self.active)
        return readonly(signed)

    @property
    def dropped(self) -> int:
        """Ground frames without a ZMP (vertical ground force at most 0.1 % of the weight, or negative).

        They are left out of :attr:`mean_distance`; this is how many.
        """
        return int(np.count_nonzero(self.ground & ~np.isfinite(self.distance)))

    @property
    def mean_distance(self) -> float:
        """Mean of :attr:`distance` over the ground frames that have a ZMP (metres).

        Never NaN: 0.0 when the clip has no ground frame (nothing to
        balance), infinity when it has ground frames but none with a ZMP.
        :attr:`dropped` counts the ground frames left out.
        """
        d = self.distance
        ok = np.isfinite(d)
        if ok.any():
            return float(d[ok].mean())
        return float("inf") if self.ground.any() else 0.0

    def polygon(self, frame: int) -> Array:
        """Support polygon of one frame as points ``(V, 3)`` on the ground (``y = 0``, or the estimated floor), via ConvexHull."""
        ground = self.__dict__.get("_ground", _LEVEL)
        pts = ground.to_plane(self.support[frame, self.active[frame]])[:, [0, 2]]
        hull = support_polygon(pts)
        return ground.to_world(np.column_stack([hull[:, 0], np.zeros(len(hull)), hull[:, 1]]))


def balance(
    motion: Motion,
    body: Body | None = None,
    *,
    contacts: Contacts | Literal["auto"] | None = "auto",
    width: float | None = None,
    fk: tuple[Array, Array] | None = None,
    roles: Mapping[str, Any] | None = None,
    floor: Floor | Literal["estimate", "y=0"] = "estimate",
) -> Balance:
    """ZMP (equation 4), support polygons and distances of a clip.

    Parameters
    ----------
    motion : Motion
    body : Body, optional
        Default :meth:`Body.from_skeleton` of the motion (measured in its
        standing pose when the skeleton's rest pose does not stand).
    contacts : "auto" or Contacts
        Planted joints: ``"auto"`` (default) detects the feet's
        (:func:`mocaplab.contacts.foot_contacts`); ``None`` (no contacts)
        raises ValueError.
    width : float, optional
        Gaussian width in frames for the accelerations (default: 5 frames at
        30 fps, scaled to the clip's rate).
    fk : (global_rotations, global_positions), optional
        The motion's forward kinematics when already at hand.
    roles : mapping of role names to joint names, optional
        Role overrides (:func:`mocaplab.roles.resolve_roles`) for the
        default body and contacts.
    floor : Floor, "estimate" or "y=0"
        The ground equation 4 is written for.  ``"estimate"`` (default):
        the plane the planted feet stand on
        (:func:`mocaplab.contacts.estimate_floor`), at the height of their
        lowest support points; a :class:`~mocaplab.contacts.Floor` gives
        the slope and its :attr:`~mocaplab.contacts.Floor.ground` the
        height; ``"y=0"`` the paper's level ground at ``y = 0``.  The ZMP
        lies on that plane and the support polygon is taken in it, so a
        walk lifted off ``y = 0`` or walked up a slope is judged as on the
        level floor.

    Returns
    -------
    Balance

    Examples
    --------
    The walk's mean ZMP distance outside the support polygon, in millimetres:

    >>> import mocaplab as ml
    >>> round(1000 * ml.physics.balance(ml.cmu("16_15")).mean_distance)
    12
    """
    known = resolve_roles(motion, roles) if body is None or isinstance(contacts, str) else None
    body = Body.from_skeleton(motion, roles=known) if body is None else body
    contacts = ground_contacts(contacts, motion, roles=known)
    _check_contacts(contacts, motion)
    w = paper_width(5.0, motion.fps) if width is None else float(width)
    body.check(motion)
    # link centres and support points in one rotation pass
    owners, offsets, column, heights = body._support_layout(motion.skeleton, tuple(contacts.joints))
    idx, all_offsets = _point_layout(body, owners, offsets)
    grot, gpos = (motion.global_rotations(), motion.global_positions()) if fk is None else fk
    pts = gpos[:, idx] + quat.rotate(grot[:, idx], all_offsets)
    raw, support = pts[:, : body.n_links], pts[:, body.n_links :]
    r, acc = _positions_and_accelerations(raw, motion.fps, width=w)
    ground = _ground_of(floor, motion, contacts, support, column)
    return _finish(motion, body, contacts, column, raw, r, acc, support, ground=ground, heights=heights)


def _rebalance(
    previous: Balance,
    motion: Motion,
    body: Body,
    contacts: Contacts,
    fk: tuple[Array, Array],
    moved: NDArray[np.bool_],
) -> Balance:
    """:func:`balance` (default width) of a motion whose joints differ only in ``moved`` (J,) from ``previous``'s.

    Only the links and support points of moved joints are recomputed (the
    smoothing works column by column, so the numbers are the very same as
    a full :func:`balance`); the ZMP and the distances are redone.
    """
    raw_prev = previous.__dict__.get("_raw")
    ground = previous.__dict__.get("_ground", _LEVEL)
    if raw_prev is None or raw_prev.shape[0] != motion.n_frames:
        return balance(motion, body, contacts=contacts, fk=fk, floor=ground.floor)
    owners, offsets, column, heights = body._support_layout(motion.skeleton, tuple(contacts.joints))
    grot, gpos = fk
    links = np.flatnonzero(moved[body.owners])
    raw, r, acc = raw_prev, previous.positions, previous.accelerations
    if links.size:
        own = body.owners[links]
        raw, r, acc = raw.copy(), r.copy(), acc.copy()
        raw[:, links] = gpos[:, own] + quat.rotate(grot[:, own], body.offsets[links])
        r[:, links], acc[:, links] = _positions_and_accelerations(raw[:, links], motion.fps, width=paper_width(5.0, motion.fps))
    support, segments = previous.support, previous.__dict__.get("_segments")
    if np.any(moved[owners]):
        support, segments = gpos[:, owners] + quat.rotate(grot[:, owners], offsets), None
    return _finish(motion, body, contacts, column, raw, r, acc, support, segments, ground=ground, heights=heights)


#: How far (metres) the heel or the toe of a foot without a toe joint may rise
#: above the rest of the foot, beyond its height in the reference pose, and
#: still bear weight: above it the foot is rolling onto its other end
#: (toe-off, heel strike) and that end leaves the support polygon.
ROLL_LIFT = 0.05


class _Ground(NamedTuple):
    """The plane equation 4 is written for: ``rotation`` takes world vectors to the plane's frame (normal +Y)."""

    rotation: Array  # (3, 3)
    origin: Array  # (3,) a point of the plane
    floor: Floor | str  # what balance(floor=...) was given, or the Floor estimated

    def to_plane(self, p: Array) -> Array:
        return p if self.identity else (p - self.origin) @ self.rotation.T

    def to_world(self, p: Array) -> Array:
        return p if self.identity else p @ self.rotation + self.origin

    @property
    def identity(self) -> bool:
        return not self.origin.any() and bool(np.all(self.rotation == np.eye(3)))


_LEVEL = _Ground(np.eye(3), np.zeros(3), "y=0")


def _plane(slope: Array, height: float, floor: Floor | str) -> _Ground:
    """The ground ``y = slope . (x, z) + height``."""
    s = np.asarray(slope, dtype=float)
    normal = np.array([-s[0], 1.0, -s[1]]) / np.sqrt(1.0 + s @ s)
    rotation = np.eye(3) if not s.any() else quat.to_matrix(quat.between(normal, [0.0, 1.0, 0.0]))
    return _Ground(np.asarray(rotation, dtype=float), np.array([0.0, float(height), 0.0]), floor)


def _ground_of(
    floor: Floor | str, motion: Motion, contacts: Contacts, support: Array, column: NDArray[np.int64]
) -> _Ground:
    """The ground of :func:`balance`'s ``floor`` option (see there)."""
    from ..contacts import Floor, estimate_floor

    if isinstance(floor, Floor):
        return _plane(floor.slope, floor.ground, floor)
    if floor == "y=0":
        return _LEVEL
    if floor != "estimate":
        raise ValueError(f"Expected `floor` to be a Floor, 'estimate' or 'y=0', got {floor!r}")
    found = estimate_floor(motion, contacts)
    if found is None:
        return _LEVEL
    planted = np.asarray(contacts.mask, dtype=bool)[:, column]
    if not planted.any():
        return _LEVEL
    slope = found.slope
    above = support[..., 1] - support[..., [0, 2]] @ slope
    height = float(np.percentile(above[planted], GROUND_PERCENTILE))
    if abs(height) <= GROUND_TOLERANCE and not slope.any():
        return _LEVEL  # feet on y = 0: the paper's ground exactly
    return _plane(slope, height, dataclasses.replace(found, slope=slope, ground=height))


#: Percentile of the planted support points' heights taken as the ground's height.
GROUND_PERCENTILE = 5.0
#: A level ground within this many metres of ``y = 0`` is ``y = 0``, the paper's ground (the lowest
#: support points of CMU walks stand 0.4-1.7 cm above it).
GROUND_TOLERANCE = 0.03


def _rolling(active: NDArray[np.bool_], column: NDArray[np.int64], heights: Array, up: Array) -> NDArray[np.bool_]:
    """``active`` without the lifted end of planted feet that have no toe joint.

    ``up`` (F, P) are the support points' heights above the ground and
    ``heights`` (P,) their heights above the foot's lowest point in the
    reference pose (NaN for points of other feet).
    """
    rolling = np.isfinite(heights)
    if not rolling.any():
        return active
    active = active.copy()
    lift = up - np.where(rolling, heights, 0.0)
    for k in np.unique(column[rolling]):
        pts = np.flatnonzero((column == k) & rolling)
        low = lift[:, pts].min(axis=1, keepdims=True)
        active[:, pts] &= lift[:, pts] - low <= ROLL_LIFT
    return active


def _finish(
    motion: Motion,
    body: Body,
    contacts: Contacts,
    column: NDArray[np.int64],
    raw: Array,
    r: Array,
    acc: Array,
    support: Array,
    segments: tuple[Array, ...] | None = None,
    *,
    ground: _Ground = _LEVEL,
    heights: Array | None = None,
) -> Balance:
    """ZMP, distances and the Balance record from link centres (raw and smoothed) and support points.

    Equation 4 and the polygon distances are computed in the frame of the
    ground plane (the world's when the ground is ``y = 0``), the ZMP and its
    projection returned on the plane in world coordinates.
    """
    mask = np.asarray(contacts.mask, dtype=bool)
    planted: NDArray[np.bool_] = np.asarray(mask.any(axis=1), dtype=bool)
    m = body.masses
    flat = ground.identity
    r_g = ground.to_plane(r)
    acc_g = acc if flat else acc @ ground.rotation.T
    gravity = GRAVITY if flat else ground.rotation @ GRAVITY
    zx, zz, ok = _zmp_xz(r_g, acc_g - gravity, m, float(m.sum() * np.linalg.norm(GRAVITY)))
    has = planted & ok
    active = mask[:, column]
    sup_g = ground.to_plane(support)
    if heights is not None:
        rolled = _rolling(active, column, heights, sup_g[..., 1])
        if rolled is not active:
            active, segments = rolled, None
    vx, vz = sup_g[..., 0], sup_g[..., 2]
    if segments is None:
        segments = _segments(vx, vz, active)
    dist, px, pz = _polygon_xz(zx, zz, has, vx, vz, active, False, segments)
    z = np.zeros((motion.n_frames, 3))
    z[:, 0], z[:, 2] = zx, zz
    proj = np.zeros((motion.n_frames, 3))
    proj[:, 0], proj[:, 2] = px, pz
    z, proj = ground.to_world(z), ground.to_world(proj)
    z[~has] = np.nan
    proj[np.isnan(px)] = np.nan
    com = (m @ raw) / body.total_mass
    # every array is new here or read-only already (shared with the Balance _rebalance started from)
    out = Balance(*(_owned(a) for a in (z, proj, dist, com, planted, support, active, r, acc)))
    # for _rebalance: the unsmoothed link centres, the support segments and the ground
    object.__setattr__(out, "_raw", readonly(raw))
    object.__setattr__(out, "_segments", tuple(readonly(s) for s in segments))
    object.__setattr__(out, "_ground", ground)
    return out


def _point_layout(body: Body, owners: NDArray[np.int64], offsets: Array) -> tuple[NDArray[np.int64], Array]:
    """Owner joints and local offsets of the link centres followed by the support points (cached)."""
    key = (id(owners), id(offsets))
    cache = body.__dict__.setdefault("_point_layout_cache", {})
    if key not in cache:
        idx = readonly(np.concatenate([body.owners, owners]))
        off = readonly(np.concatenate([body.offsets, offsets]))
        cache[key] = (idx, off, owners, offsets)  # keep the keyed arrays alive
    return cache[key][:2]


def zmp_distance(
    motion: Motion,
    body: Body | None = None,
    *,
    contacts: Contacts | Literal["auto"] | None = "auto",
    roles: Mapping[str, Any] | None = None,
) -> Array:
    """Distance of the ZMP outside the support polygon, shape (F,); 0 inside, NaN in flight.

    Options as for :func:`balance`.

    Parameters
    ----------
    motion : Motion
    body : Body, optional
        Default :meth:`Body.from_skeleton` of the motion.
    contacts : "auto" or Contacts
        Planted joints (see :func:`balance`).
    roles : mapping, optional
        Joint-role overrides for the default body and contacts.

    Returns
    -------
    ndarray, shape (F,)
        Metres: ``balance(motion, ...).distance``.

    Examples
    --------
    >>> import mocaplab as ml
    >>> d = ml.physics.zmp_distance(ml.cmu("16_15").resample(30)[:60])
    >>> d.shape, round(1000 * float(d.mean()), 1)
    ((60,), 12.5)
    """
    return balance(motion, body, contacts=contacts, roles=roles).distance


def _ensure_sequence(motions: Motion | Sequence[Motion]) -> list[Motion]:
    if isinstance(motions, Motion):
        return [motions]
    out = list(motions)
    for k, m in enumerate(out):
        if not isinstance(m, Motion):
            raise TypeError(f"Expected Motion objects, got {type(m).__name__} at position {k}")
    if not out:
        raise ValueError("Expected at least one motion, got none")
    return out
