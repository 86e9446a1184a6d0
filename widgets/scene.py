"""The 3D viewer's scene as plain arrays: what is drawn, where, and from where it is seen.

This module holds the geometry of :class:`~mocaplab.widgets.viewer.MotionViewer`
and nothing that draws: numpy (and the core's roles) only, no pyvista, VTK,
trame or ipywidgets, so that it can be imported and tested without a 3D stack
(a test imports it in a fresh interpreter and checks that neither ``pyvista``
nor ``vtk`` was loaded).  Its neighbours use these arrays:

* :mod:`mocaplab.widgets.viewer` writes them into pyvista meshes (the kernel's
  render window: the ``static``, ``trame`` and ``server`` backends);
* :mod:`mocaplab.widgets.vtkjs_page` sends them to the browser, which draws
  them with vtk.js (the ``client`` backend).

What is drawn
-------------
A character is its drawn points on every frame, shape ``(F, J + E, 3)``
(joints, then end sites) and its bones as pairs of indices into them
(:func:`character_geometry`); joints above the path joint (a static reference
joint at the origin over a travelling pelvis) are left out, so the body looks
the same whatever the skeleton's layout.  Bones are open tubes
(:func:`tube_points`, :func:`tube_faces`), joints copies of one sphere
(:class:`SphereSet`), both of fixed topology: a new frame only moves points.
Overlays (:class:`Overlay`) are extra points, polylines or polygons that move
with the time.  The ground is a grid of 0.5 m squares at y = 0
(:func:`ground_grid`).

Seen from where
---------------
:func:`fit_view` places the nearest perspective camera that sees a box
(:func:`box_corners`); all lengths are metres, y is up.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocaplab.editing.paths import with_roles
from mocaplab.motion import Motion

__all__ = [
    "FILL",
    "TAB20",
    "character_colors",
    "srgb_to_lab",
    "Character",
    "Overlay",
    "OverlayData",
    "SphereSet",
    "as_motions",
    "box_corners",
    "character_geometry",
    "check_overlay_data",
    "clock_of",
    "fit_view",
    "ground_grid",
    "overlay_cells",
    "scene_bounds",
    "tube_faces",
    "tube_points",
]

#: Matplotlib's tab20 colours, the dark ten (tab10) first: the first characters' colours everywhere.
TAB20 = (
    "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf",
    "#aec7e8", "#ffbb78", "#98df8a", "#ff9896", "#c5b0d5", "#c49c94", "#f7b6d2", "#c7c7c7", "#dbdb8d", "#9edae5",
)  # fmt: skip
#: The first characters' colours: tab20 less its light grey (#c7c7c7 is lost on the ground grid's #bbbbbb lines).
_SEEDS = tuple(c for c in TAB20 if c != "#c7c7c7")
# Share of the picture's area the characters' box may fill (the rest is margin).
FILL = 0.9

# sRGB (D65) to CIE XYZ, and the D65 white point (IEC 61966-2-1; CIE 15)
_SRGB_TO_XYZ = np.array(
    [[0.4124564, 0.3575761, 0.1804375], [0.2126729, 0.7151522, 0.0721750], [0.0193339, 0.1191920, 0.9503041]]
)
_WHITE_D65 = np.array([0.95047, 1.0, 1.08883])
# the colours added after tab20: lightness and chroma (CIELAB) that read on the white page and the grey ground
_LIGHTNESS = (30.0, 85.0)
_MIN_CHROMA = 10.0
_GRID_LEVELS = 18  # candidate sRGB colours: 18 levels per channel


def srgb_to_lab(colors: ArrayLike | Sequence[str]) -> NDArray[np.float64]:
    """CIELAB (D65) coordinates of sRGB colours: ``L`` in [0, 100], ``a``, ``b`` about [-128, 127].

    Parameters
    ----------
    colors : sequence of str ("#rrggbb") or array_like, shape (..., 3)
        Hex strings, or sRGB values in [0, 1].

    Returns
    -------
    ndarray, shape (..., 3)
        ``(L, a, b)``; the CIE76 colour difference of two colours is the
        Euclidean distance of their rows.

    Examples
    --------
    >>> np.round(srgb_to_lab(["#ff0000"]), 2).tolist()
    [[53.24, 80.09, 67.2]]
    """
    if isinstance(colors, (list, tuple)) and colors and all(isinstance(c, str) for c in colors):
        bad = [c for c in colors if len(c) != 7 or c[0] != "#"]
        if bad:
            raise ValueError(f"Expected colours as '#rrggbb', got {bad[0]!r}")
        rgb = np.array([[int(c[i : i + 2], 16) for i in (1, 3, 5)] for c in colors], dtype=float) / 255.0
    else:
        rgb = np.asarray(colors, dtype=float)
    if rgb.shape[-1:] != (3,):
        raise ValueError(f"Expected `colors` of shape (..., 3), got {rgb.shape}")
    linear = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    xyz = linear @ _SRGB_TO_XYZ.T / _WHITE_D65
    eps = (6.0 / 29.0) ** 3
    f = np.where(xyz > eps, np.cbrt(xyz), xyz / (3 * (6.0 / 29.0) ** 2) + 4.0 / 29.0)
    return np.stack([116.0 * f[..., 1] - 16.0, 500.0 * (f[..., 0] - f[..., 1]), 200.0 * (f[..., 1] - f[..., 2])], -1)


@functools.lru_cache(maxsize=8)
def _palette(count: int) -> tuple[str, ...]:
    """The first ``count`` character colours (see :func:`character_colors`); a multiple of 80 is asked for."""
    levels = np.linspace(0.0, 1.0, _GRID_LEVELS)
    grid = np.stack(np.meshgrid(levels, levels, levels, indexing="ij"), axis=-1).reshape(-1, 3)
    lab = srgb_to_lab(grid)
    keep = (lab[:, 0] >= _LIGHTNESS[0]) & (lab[:, 0] <= _LIGHTNESS[1]) & (np.hypot(lab[:, 1], lab[:, 2]) >= _MIN_CHROMA)
    grid, lab = grid[keep], lab[keep]
    chosen = list(_SEEDS[:count])
    # farthest-point sampling: each new colour is the candidate farthest (CIE76) from every colour chosen so far
    nearest = np.min(np.linalg.norm(lab[:, None, :] - srgb_to_lab(list(_SEEDS))[None], axis=-1), axis=1)
    while len(chosen) < count:
        j = int(np.argmax(nearest))
        chosen.append("#" + "".join(f"{round(255 * v):02x}" for v in grid[j]))
        nearest = np.minimum(nearest, np.linalg.norm(lab - lab[j], axis=-1))
    return tuple(chosen)


def character_colors(n: int) -> list[str]:
    """Distinct colours of ``n`` characters, the same in the 3D views and the matplotlib plots.

    The first 19 are matplotlib's tab20 less its light grey (which vanishes
    on the ground grid), tab10's dark ten first, so two or three characters
    look as they always did; each further colour is the sRGB colour farthest
    in CIELAB (CIE76) from all colours before it, among those light and
    saturated enough to read on the white page and the grey ground.  Colour
    ``k`` does not depend on ``n``.  Any two of the first 80 differ by a
    CIE76 distance above 16 (tab20's own closest pair).

    Parameters
    ----------
    n : int
        How many characters (>= 0).

    Returns
    -------
    list of str
        ``"#rrggbb"`` colours.

    Examples
    --------
    >>> character_colors(3)
    ['#1f77b4', '#ff7f0e', '#2ca02c']
    >>> len(set(character_colors(80)))
    80
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
        raise ValueError(f"Expected `n` to be an integer >= 0, got {n!r}")
    count = 80 * max(1, -(-int(n) // 80))
    return list(_palette(count)[: int(n)])


OverlayData = ArrayLike | Sequence[ArrayLike] | Callable[[float], ArrayLike]
OverlayKind = Literal["points", "lines", "polygon"]


# --------------------------------------------------------------------------
# camera
# --------------------------------------------------------------------------
def box_corners(lo: ArrayLike, hi: ArrayLike, floor: float, top: float) -> NDArray[np.float64]:
    """The 8 corners of the box ``[lo, hi]`` in x and z and ``[floor, top]`` in y, shape (8, 3)."""
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (floor, top) for z in (lo[2], hi[2])])


def fit_view(
    corners: ArrayLike,
    direction: ArrayLike,
    up: ArrayLike,
    *,
    view_angle: float,
    aspect: float,
    fill: float = FILL,
    top_band: float = 0.0,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Focal point and position of the nearest perspective camera that sees every corner.

    The camera looks along ``-direction`` with ``up`` up.  A point at depth
    ``z`` in front of it, ``x`` to the right and ``y`` up (camera axes) is
    inside the picture when ``|x| <= fill * aspect * tan(view_angle / 2) * z``
    and ``-1 <= y / (fill * tan(view_angle / 2) * z) <= 1 - 2 * top_band``:
    the top ``top_band`` of the picture's height is kept free (a toolbar lies
    there).  The camera distance is the smallest for which both ranges hold
    for every corner (found by bisection: each range only widens with the
    distance); the focal point then centres the corners between the limits.

    Parameters
    ----------
    corners : array_like, shape (n, 3)
        Points that must be inside the picture (a box's corners).
    direction : array_like, shape (3,)
        From the scene towards the camera (any length).
    up : array_like, shape (3,)
        The view-up vector.
    view_angle : float
        Vertical view angle in degrees (VTK's default is 30).
    aspect : float
        Picture width over height.
    fill : float
        Largest share of the half-width and half-height a corner may reach.
    top_band : float
        Share of the picture's height kept free at its top, in [0, 0.5).

    Returns
    -------
    focal_point, position : ndarray, shape (3,)

    Examples
    --------
    >>> import numpy as np
    >>> cube = [[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
    >>> focal, position = fit_view(cube, [0, 0, 1], [0, 1, 0], view_angle=90.0, aspect=1.0, fill=1.0)
    >>> np.round(position, 6).tolist()   # the front face's corners on the picture's edges
    [0.0, 0.0, 2.0]
    """
    pts = np.asarray(corners, dtype=float).reshape(-1, 3)
    w = np.asarray(direction, dtype=float)
    w = w / np.linalg.norm(w)
    right = np.cross(-w, np.asarray(up, dtype=float))
    right /= np.linalg.norm(right)
    upv = np.cross(right, -w)
    centre = pts.mean(axis=0)
    d = pts - centre
    a, x, y = d @ w, d @ right, d @ upv
    ty = fill * math.tan(math.radians(view_angle) / 2.0)
    tx, top = ty * aspect, 1.0 - 2.0 * float(top_band)

    def ranges(dist: float) -> tuple[float, float, float, float]:
        z = dist - a
        return (
            float(np.max(x - tx * z)),
            float(np.min(x + tx * z)),
            float(np.max(y - top * ty * z)),
            float(np.min(y + ty * z)),
        )

    def fits(dist: float) -> bool:
        x0, x1, y0, y1 = ranges(dist)
        return x0 <= x1 and y0 <= y1

    size = float(np.ptp(pts, axis=0).max()) + 1e-3
    near = float(a.max()) + 1e-6
    far = near + size
    while not fits(far):
        far = near + 2.0 * (far - near)
    for _ in range(60):
        mid = 0.5 * (near + far)
        near, far = (near, mid) if fits(mid) else (mid, far)
    x0, x1, y0, y1 = ranges(far)
    focal = centre + 0.5 * (x0 + x1) * right + 0.5 * (y0 + y1) * upv
    return focal, focal + far * w


# --------------------------------------------------------------------------
# fixed-topology geometry: tubes and spheres whose points move
# --------------------------------------------------------------------------
def tube_faces(n_bones: int, sides: int) -> NDArray[np.int64]:
    """VTK face array of ``n_bones`` open tubes with ``sides`` quads each (the points of :func:`tube_points`).

    Returns
    -------
    ndarray, shape (n_bones * sides * 5,)
        ``4, i0, i1, i2, i3`` per quad.
    """
    s = np.arange(sides)
    base = (np.arange(n_bones) * 2 * sides)[:, None]
    quads = np.stack([base + s, base + (s + 1) % sides, base + sides + (s + 1) % sides, base + sides + s], axis=-1)
    return np.concatenate([np.full((n_bones, sides, 1), 4), quads], axis=-1).reshape(-1)


def tube_points(
    a: NDArray[np.float64], b: NDArray[np.float64], radius: float, sides: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Points and normals of open tubes from ``a`` to ``b``: a ring of ``sides`` points at each end.

    Parameters
    ----------
    a, b : ndarray, shape (B, 3)
        The bones' ends.
    radius : float
        Distance of every point from its bone's axis.
    sides : int
        Points per ring.

    Returns
    -------
    points, normals : ndarray, shape (B * 2 * sides, 3)
        Bone by bone, the ring at ``a`` then the ring at ``b``; the normals
        are the unit radial directions.
    """
    d = b - a
    length = np.linalg.norm(d, axis=-1, keepdims=True)
    axis = np.where(length > 1e-9, d / np.maximum(length, 1e-12), [0.0, 1.0, 0.0])
    helper = np.where(np.abs(axis[:, :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    v = np.cross(axis, u)
    theta = 2 * np.pi * np.arange(sides) / sides
    ring = np.cos(theta)[None, :, None] * u[:, None] + np.sin(theta)[None, :, None] * v[:, None]  # (B, S, 3)
    pts = np.stack([a[:, None] + radius * ring, b[:, None] + radius * ring], axis=1)  # (B, 2, S, 3)
    normals = np.broadcast_to(ring[:, None], pts.shape)
    return pts.reshape(-1, 3), normals.reshape(-1, 3)


@dataclass
class SphereSet:
    """``n`` copies of one sphere mesh, moved by translating each copy.

    The sphere itself (its unit points and triangles) comes from whoever
    draws it (:func:`mocaplab.widgets.viewer.sphere_set` takes pyvista's);
    :meth:`from_unit` scales it.

    Attributes
    ----------
    template : ndarray, shape (P, 3)
        The sphere's points around the origin, at its radius.
    template_normals : ndarray, shape (P, 3)
        Their unit normals.
    template_faces : ndarray, shape (C, 3)
        Its triangles, indices into ``template``.
    """

    template: NDArray[np.float64]
    template_normals: NDArray[np.float64]
    template_faces: NDArray[np.int64]

    @classmethod
    def from_unit(cls, unit_points: ArrayLike, faces: ArrayLike, radius: float) -> SphereSet:
        """The set of the unit sphere ``unit_points`` (P, 3) with triangles ``faces`` (C, 3), scaled to ``radius``."""
        unit = np.asarray(unit_points, dtype=float)
        return cls(unit * radius, unit, np.asarray(faces, dtype=np.int64))

    def faces(self, n: int) -> NDArray[np.int64]:
        """VTK face array of ``n`` copies of the template sphere, shape (n * C * 4,)."""
        tris = self.template_faces[None] + (np.arange(n) * len(self.template))[:, None, None]  # (n, C, 3)
        return np.concatenate([np.full(tris.shape[:2] + (1,), 3), tris], axis=-1).reshape(-1)

    def points(self, centres: NDArray[np.float64]) -> NDArray[np.float64]:
        """The points of one copy around each of ``centres`` (n, 3), shape (n * P, 3)."""
        return (centres[:, None] + self.template[None]).reshape(-1, 3)

    def normals(self, n: int) -> NDArray[np.float64]:
        """The normals of ``n`` copies, shape (n * P, 3)."""
        return np.tile(self.template_normals, (n, 1))


# --------------------------------------------------------------------------
# characters
# --------------------------------------------------------------------------
def as_motions(motions: Motion | Sequence[Motion]) -> list[Motion]:
    """``motions`` as a non-empty list of Motion (a single Motion is one character)."""
    items = [motions] if isinstance(motions, Motion) else list(motions)
    if not items:
        raise ValueError("Expected at least one Motion in `motions`, got none")
    for k, m in enumerate(items):
        if not isinstance(m, Motion):
            raise TypeError(f"Expected `motions[{k}]` to be a Motion, got {type(m).__name__}")
    return items


def clock_of(motions: Sequence[Motion], fps: float | None = None) -> tuple[float, int]:
    """The viewer's clock for ``motions``: its rate (``fps``, default the highest) and its frame count.

    Clock frame ``i`` is time ``i / rate``; the last one is the end of the longest motion.
    """
    rate = fps if fps is not None else max(m.fps for m in motions)
    return rate, int(np.floor(max(m.duration for m in motions) * rate + 1e-9)) + 1


def character_geometry(
    motion: Motion, roles: Mapping[str, Any] | None = None, *, end_sites: bool = True
) -> tuple[NDArray[np.float64], NDArray[np.int64], int]:
    """The drawn points of ``motion`` on every frame, its bones, and the index of its path joint among them.

    Joints above the path joint (a static reference joint at the origin over
    a travelling pelvis) are not drawn, nor the "bone" from them to the
    pelvis (the travel over the ground): the body looks the same whatever the
    skeleton's layout.

    Parameters
    ----------
    motion : Motion
    roles : mapping of role name to joint name, optional
        Roles fixed by hand (:func:`mocaplab.editing.paths.with_roles`); the path joint is their pelvis.
    end_sites : bool
        Add the end sites (toe tips, head top, fingers) after the joints, with their bones.

    Returns
    -------
    positions : ndarray, shape (F, J + E, 3)
        Drawn joints, then drawn end sites.
    segments : ndarray, shape (B, 2)
        Bones as pairs of indices into ``positions``.
    path_joint : int
        Index in ``positions`` of the path joint (the pelvis role).
    """
    sk = motion.skeleton
    pj = with_roles(motion, roles).path_joint
    parents = np.asarray(sk.parents)
    drawn = np.ones(sk.n_joints, bool)
    j = int(parents[pj])
    while j >= 0:
        drawn[j] = False
        j = int(parents[j])
    idx = np.flatnonzero(drawn)
    new = np.full(sk.n_joints, -1, dtype=np.int64)
    new[idx] = np.arange(len(idx))
    pos = motion.global_positions()[:, idx]
    child = np.flatnonzero(drawn & (parents >= 0) & drawn[np.maximum(parents, 0)])
    segs = np.stack([new[parents[child]], new[child]], axis=1)
    if end_sites and sk.end_site_parents.size:
        esp = np.asarray(sk.end_site_parents)
        ok = drawn[esp]
        pos = np.concatenate([pos, motion.end_site_positions()[:, ok]], axis=1)
        ends = np.arange(len(idx), len(idx) + int(ok.sum()))
        segs = np.concatenate([segs, np.stack([new[esp[ok]], ends], axis=1)])
    return pos, segs, int(new[pj])


@dataclass
class Character:
    """One character of the scene: its drawn points and bones (:func:`character_geometry`), colour and name.

    ``bones``, ``joints`` and ``actors`` are the drawn meshes and their
    actors, filled by the viewer that draws the character (None without one).
    """

    motion: Motion
    color: str
    label: str
    positions: NDArray[np.float64]  # (F, J + E, 3): drawn joints then end sites
    segments: NDArray[np.int64]  # (B, 2) indices into the positions
    path_joint: int = 0  # index in `positions` of the joint the camera follows (the pelvis role)
    bones: Any = None  # pyvista.PolyData
    joints: Any = None  # pyvista.PolyData
    actors: tuple[Any, ...] = ()

    def frame_at(self, t: float) -> int:
        """The character's frame at time ``t`` seconds: the nearest, held at its ends."""
        return int(min(max(round(t * self.motion.fps), 0), self.motion.n_frames - 1))

    def anchor(self, t: float) -> NDArray[np.float64]:
        """World position of the path joint at time ``t``, shape (3,)."""
        return self.positions[self.frame_at(t), self.path_joint]


def scene_bounds(characters: Sequence[Character], pad: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Box (lo, hi) of every drawn point of every character over its whole clip, grown by ``pad``."""
    all_pts = np.concatenate([c.positions.reshape(-1, 3) for c in characters])
    return all_pts.min(axis=0) - pad, all_pts.max(axis=0) + pad


def ground_grid(
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
    extent: tuple[float, float, float, float] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], tuple[float, float, float, float]] | None:
    """The ground's grid lines under the box ``[lo, hi]``: 0.5 m squares with a margin of at least 1 m.

    Parameters
    ----------
    lo, hi : ndarray, shape (3,)
        The box to lie under (only x and z are read).
    extent : (x0, x1, z0, z1), optional
        The grid already laid.

    Returns
    -------
    (xs, zs, extent) or None
        The x and z of the lines and the grid's extent; None when ``extent``
        already covers the box (the grid stays).
    """
    if extent is not None:
        x0, x1, z0, z1 = extent
        if x0 <= lo[0] and hi[0] <= x1 and z0 <= lo[2] and hi[2] <= z1:
            return None
    margin = 1.0
    x0, x1 = np.floor(lo[0] - margin), np.ceil(hi[0] + margin)
    z0, z1 = np.floor(lo[2] - margin), np.ceil(hi[2] + margin)
    xs = np.linspace(x0, x1, int(round((x1 - x0) / 0.5)) + 1)  # 0.5 m squares
    zs = np.linspace(z0, z1, int(round((z1 - z0) / 0.5)) + 1)
    return xs, zs, (float(x0), float(x1), float(z0), float(z1))


# --------------------------------------------------------------------------
# overlays
# --------------------------------------------------------------------------
@dataclass
class Overlay:
    """Named extra geometry that moves with the time: points, a polyline or a polygon.

    ``data`` is checked by :func:`check_overlay_data`; ``style`` holds the
    drawing options (``radius``, ``width``, ``closed``, ``fill``,
    ``opacity``).  ``mesh``, ``actor`` and ``count`` (points in the mesh) are
    the viewer's.
    """

    name: str
    kind: OverlayKind
    data: Any
    fps: float
    color: str
    style: dict[str, Any]
    mesh: Any = None
    actor: Any = None
    count: int = -1

    def at(self, t: float) -> NDArray[np.float64]:
        """The overlay's points at time ``t``: (k, 3) with NaN rows removed."""
        if callable(self.data):
            pts = np.asarray(self.data(float(t)), dtype=float)
        elif isinstance(self.data, np.ndarray) and self.data.ndim == 2:
            pts = self.data
        else:
            n = len(self.data)
            i = int(min(max(round(t * self.fps), 0), n - 1))
            pts = np.asarray(self.data[i], dtype=float)
        pts = pts.reshape(-1, 3) if pts.size else np.zeros((0, 3))
        return pts[np.all(np.isfinite(pts), axis=1)]


def check_overlay_data(name: str, data: Any) -> Any:
    """Overlay ``data`` in the form :meth:`Overlay.at` reads: a callable, an array (F, k, 3) or (k, 3), or a list.

    Raises
    ------
    ValueError
        Naming the overlay, when ``data`` is none of (F, k, 3), (k, 3), a list of (k_i, 3) or a callable.
    """
    if callable(data):
        return data
    if isinstance(data, np.ndarray) or (isinstance(data, Sequence) and data and np.ndim(data[0]) == 1):
        arr = np.asarray(data, dtype=float)
        if arr.ndim in (2, 3) and arr.shape[-1] == 3:
            return arr
        raise ValueError(
            f"Expected overlay {name!r} data of shape (F, k, 3) or (k, 3), a list of (k_i, 3) arrays "
            f"or a callable of time, got an array of shape {arr.shape}"
        )
    if isinstance(data, Sequence) and len(data) > 0:
        frames = [np.asarray(d, dtype=float).reshape(-1, 3) if np.size(d) else np.zeros((0, 3)) for d in data]
        return frames
    raise ValueError(
        f"Expected overlay {name!r} data: (F, k, 3), (k, 3), a list of (k_i, 3) or a callable, got {data!r}"
    )


def overlay_cells(k: int, *, closed: bool, fill: bool) -> tuple[NDArray[np.int64], NDArray[np.int64] | None]:
    """VTK cells of a polyline through ``k`` points (``closed``: back to the first) and, with ``fill``, its fan.

    Returns
    -------
    lines : ndarray
        One line cell: its point count, then the point indices.
    faces : ndarray or None
        ``3, 0, i, i + 1`` per triangle of the fan from point 0 (k >= 3 and
        ``fill``), else None.
    """
    order = np.r_[np.arange(k), 0] if closed and k > 2 else np.arange(k)
    faces = None
    if fill and k >= 3:
        tris = np.stack([np.zeros(k - 2, dtype=np.int64), np.arange(1, k - 1), np.arange(2, k)], axis=1)
        faces = np.concatenate([np.full((k - 2, 1), 3), tris], axis=1).reshape(-1)
    return np.r_[len(order), order], faces
