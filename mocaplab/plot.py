"""Static matplotlib drawings for lessons and reports.

This is the only module of the core that imports matplotlib, and it does so
lazily, inside each function, so ``import mocaplab`` never loads it.  Every
function draws into the Axes it is given (``ax=``) or into a new figure made
with :func:`matplotlib.pyplot.subplots` (so it shows inline in Jupyter), and
returns the Axes.

Axes conventions
----------------
* World coordinates are metres, Y up, ground plane ``(x, z)``
  (see :mod:`mocaplab.motion`).
* In 3D plots the world axes are shown cyclically permuted, matplotlib's
  ``(X, Y, Z) = (z, x, y)``, so that the world's up axis is matplotlib's
  vertical axis and the view stays right-handed (no mirror image).
* Top-down plots (:func:`root_path`, ``projection="top"``) look down from
  +Y: ``x`` to the right and ``z`` **down the page** (the vertical axis is
  inverted), equal aspect.  This is what a camera above a right-handed, Y-up
  scene sees (with ``z`` up the page the scene would be mirrored, turning a
  left turn into a right turn), and it agrees with the path editor
  (:class:`mocaplab.widgets.PathEditor`).  The inversion is idempotent:
  drawing several top views into one Axes never flips it back, so callers
  must not invert the axis themselves.

Examples
--------
>>> import matplotlib
>>> matplotlib.use("Agg")
>>> from mocaplab.data import cmu                      # doctest: +SKIP
>>> walk = cmu("16_15")                                # doctest: +SKIP
>>> ax = skeleton(walk, 0)                             # doctest: +SKIP
>>> ax = root_path(walk)                               # doctest: +SKIP
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import quat
from .contacts import Contacts
from .motion import Motion
from .roles import parse_name

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes

__all__ = ["skeleton", "root_path", "joint_curves", "contact_timeline", "literal", "COLORS"]

#: Default colours of successive characters (matplotlib's tab10 cycle).
COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f")

Projection = Literal["3d", "front", "side", "top"]
# world axis indices shown on (horizontal, vertical) of each 2D projection
_PLANES = {"front": (0, 1), "side": (2, 1), "top": (0, 2)}
_AXIS_NAMES = ("x", "y", "z")


def literal(text: object) -> str:
    """Text from data (a joint, clip or file name) that matplotlib shows as written.

    Matplotlib reads text between two ``$`` as mathtext: a clip named
    ``$\\foo$`` fails to draw (an unknown symbol), and ``$x$`` turns italic.
    Every ``$`` is escaped, so mathtext never sees the text.  Use it for every
    label, title or tick built from data (the widgets do too).

    Parameters
    ----------
    text : object
        Shown with ``str()``.

    Returns
    -------
    str

    Examples
    --------
    >>> print(literal("cost in $"))
    cost in \\$
    """
    return str(text).replace("$", "\\$")


def _new_axes(ax: Axes | None, *, three_d: bool = False, figsize: tuple[float, float] = (6.0, 4.0)) -> Axes:
    if ax is not None:
        if three_d and getattr(ax, "name", "") != "3d":
            raise ValueError(f"Expected a 3D Axes (projection='3d') for `ax`, got a {getattr(ax, 'name', '?')!r} Axes")
        return ax
    import matplotlib.pyplot as plt

    if three_d:
        fig = plt.figure(figsize=figsize)
        return fig.add_subplot(projection="3d")
    _, new = plt.subplots(figsize=figsize)
    return new


def _check_motion(motion: object, what: str = "motion") -> Motion:
    if not isinstance(motion, Motion):
        raise TypeError(f"Expected `{what}` to be a Motion, got {type(motion).__name__}")
    return motion


def _frame_index(motion: Motion, frame: int) -> int:
    f = int(frame)
    if not -motion.n_frames <= f < motion.n_frames:
        raise IndexError(f"Expected `frame` in [0, {motion.n_frames}), got {frame}")
    return f % motion.n_frames


def _drawn(motion: Motion) -> NDArray[np.bool_]:
    """Joints that are drawn, shape (J,): all but those above the path joint.

    A static reference joint above a travelling pelvis (a common export
    layout) is not part of the body, nor is its "bone" to the pelvis (the
    travel over the ground).
    """
    parents = np.asarray(motion.skeleton.parents)
    drawn = np.ones(len(parents), bool)
    j = int(parents[motion.path_joint])
    while j >= 0:
        drawn[j] = False
        j = int(parents[j])
    return drawn


def _bones(motion: Motion, frame: int, end_sites: bool) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Joint positions (J, 3) and bone segments (B, 2, 3) at one frame (the drawn joints' bones)."""
    sk = motion.skeleton
    pos = motion.global_positions()[frame]
    drawn = _drawn(motion)
    parents = np.asarray(sk.parents)
    child = np.flatnonzero(drawn & (parents >= 0) & drawn[np.maximum(parents, 0)])
    segs = [np.stack([pos[parents[child]], pos[child]], axis=1)]
    if end_sites and sk.end_site_parents.size:
        esp = np.asarray(sk.end_site_parents)
        ends = motion.end_site_positions()[frame][drawn[esp]]
        segs.append(np.stack([pos[esp[drawn[esp]]], ends], axis=1))
    return pos, np.concatenate(segs, axis=0)


def _top_view(ax: Axes) -> None:
    """Make ``ax`` a view from above: z grows down the page (idempotent)."""
    if not ax.yaxis_inverted():
        ax.invert_yaxis()


def _to_mpl3d(p: NDArray[np.float64]) -> NDArray[np.float64]:
    """World (x, y, z) to matplotlib 3D (X, Y, Z) = (z, x, y)."""
    return p[..., [2, 0, 1]]


def _set_equal_3d(ax: Any, points: NDArray[np.float64], margin: float = 0.1) -> None:
    lo, hi = points.min(axis=0), points.max(axis=0)
    centre, half = (lo + hi) / 2, max(float((hi - lo).max()) / 2, 0.05) + margin
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(max(centre[2] - half, min(0.0, lo[2])), centre[2] + half)
    ax.set_box_aspect((1, 1, (ax.get_zlim()[1] - ax.get_zlim()[0]) / (2 * half)))


# --------------------------------------------------------------------------
def skeleton(
    motion: Motion,
    frame: int = 0,
    *,
    ax: Axes | None = None,
    projection: Projection = "3d",
    color: str | None = None,
    highlight: Sequence[str] = (),
    highlight_color: str = "#d62728",
    end_sites: bool = True,
    ground: bool = True,
    label: str | None = None,
    linewidth: float = 2.5,
) -> Axes:
    """Draw the skeleton at one frame: bones as lines, joints as dots.

    Parameters
    ----------
    motion : Motion
    frame : int
        Frame index (negative counts from the end).
    ax : Axes, optional
        Where to draw; a 3D Axes when ``projection="3d"``.  Default: a new figure.
    projection : {"3d", "front", "side", "top"}
        ``"3d"``: perspective view; ``"front"``: (x, y); ``"side"``: (z, y);
        ``"top"``: (x, z) seen from above, z down the page (see the module
        notes).
    color : str, optional
        Bone colour (default the first of :data:`COLORS`).
    highlight : sequence of str
        Joint names drawn larger in ``highlight_color`` (e.g. contact joints).
    end_sites : bool
        Also draw the bones to the BVH end sites (toe tips, head top, fingers).
    ground : bool
        Draw the ground line or plane (y = 0) under the character.
    label : str, optional
        Legend label (default the motion's name).
    linewidth : float

    Returns
    -------
    Axes
    """
    motion = _check_motion(motion)
    if projection not in ("3d", *_PLANES):
        raise ValueError(f"Expected `projection` in {('3d', *_PLANES)}, got {projection!r}")
    f = _frame_index(motion, frame)
    pos, segs = _bones(motion, f, end_sites)
    body = pos[_drawn(motion)]
    color = color or COLORS[0]
    label = literal(motion.name if label is None else label)
    marked = np.array([motion.skeleton.index(n) for n in highlight], dtype=np.int64)
    if projection == "3d":
        ax3: Any = _new_axes(ax, three_d=True)  # mpl_toolkits.mplot3d.Axes3D
        from mpl_toolkits.mplot3d.art3d import Line3DCollection

        ax3.add_collection3d(Line3DCollection(_to_mpl3d(segs), colors=color, linewidths=linewidth, label=label or None))
        p = _to_mpl3d(pos)
        q = _to_mpl3d(body)
        ax3.scatter(q[:, 0], q[:, 1], q[:, 2], s=10, color=color, depthshade=False)
        if marked.size:
            ax3.scatter(*_to_mpl3d(pos[marked]).T, s=50, color=highlight_color, depthshade=False)
        if ground:
            lo, hi = q.min(axis=0) - 0.3, q.max(axis=0) + 0.3
            gx, gy = np.meshgrid([lo[0], hi[0]], [lo[1], hi[1]])
            ax3.plot_surface(gx, gy, np.zeros_like(gx), color="0.85", alpha=0.35, zorder=-1)
        under = p[motion.path_joint]  # the ground under the pelvis, wherever joint 0 is
        _set_equal_3d(ax3, np.concatenate([_to_mpl3d(segs).reshape(-1, 3), [[under[0], under[1], 0.0]]]))
        ax3.set_xlabel("z (m)")
        ax3.set_ylabel("x (m)")
        ax3.set_zlabel("y (m, up)")
        ax = ax3
    else:
        ax = _new_axes(ax)
        from matplotlib.collections import LineCollection

        h, v = _PLANES[projection]
        ax.add_collection(
            LineCollection(list(segs[:, :, [h, v]]), colors=color, linewidths=linewidth, label=label or None)
        )
        ax.scatter(body[:, h], body[:, v], s=10, color=color, zorder=3)
        if marked.size:
            ax.scatter(pos[marked, h], pos[marked, v], s=50, color=highlight_color, zorder=4)
        if ground and v == 1:
            ax.axhline(0.0, color="0.5", linewidth=1, zorder=0)
        ax.set_aspect("equal", adjustable="datalim")
        ax.autoscale_view()
        ax.set_xlabel(f"{_AXIS_NAMES[h]} (m)")
        ax.set_ylabel(f"{_AXIS_NAMES[v]} (m)")
        if projection == "top":
            _top_view(ax)
    title = f"{motion.name + ', ' if motion.name else ''}frame {f} (t = {f / motion.fps:.2f} s)"
    ax.set_title(literal(title))
    return ax


# --------------------------------------------------------------------------
def _ground_path(item: object, k: int) -> tuple[NDArray[np.float64], str]:
    if isinstance(item, Motion):
        return np.asarray(item.pelvis_positions)[:, [0, 2]], item.name
    a = np.asarray(item, dtype=float)
    if a.ndim == 2 and a.shape[1] == 2:
        return a, ""
    if a.ndim == 2 and a.shape[1] == 3:
        return a[:, [0, 2]], ""
    raise ValueError(
        f"Expected item {k} of `motions` to be a Motion or an (F, 2) (x, z) / (F, 3) path, got shape {a.shape}"
    )


def root_path(
    motions: Motion | ArrayLike | Sequence[Motion | ArrayLike],
    *,
    ax: Axes | None = None,
    colors: Sequence[str] | None = None,
    labels: Sequence[str] | None = None,
    ticks: float | None = 0.5,
    linewidth: float = 2.0,
) -> Axes:
    """Top-down view of root paths on the ground plane.

    The view looks down from above (+Y): ``x`` to the right and ``z`` down the
    page, i.e. the Axes' y axis is inverted (once, however many times this
    draws into the same Axes), as in
    :class:`mocaplab.widgets.PathEditor`.  A walk turning to its left turns
    to the left on the page.  Do not call ``ax.invert_yaxis()`` afterwards:
    that would mirror the scene again.

    Parameters
    ----------
    motions : Motion, ndarray or a list of them
        Each item is a Motion (the ``(x, z)`` of its path joint, the pelvis
        :attr:`~mocaplab.motion.Motion.path_joint`, is drawn), an ``(F, 2)``
        array of ``(x, z)`` points or an ``(F, 3)`` array of world positions.
    ax : Axes, optional
    colors, labels : sequence of str, optional
        One per path (default :data:`COLORS` and each motion's name).
    ticks : float or None
        For Motions, a dot every ``ticks`` seconds along the path, to show
        speed (``None``: no dots).  Start is a circle, end a square.
    linewidth : float

    Returns
    -------
    Axes
    """
    items: list[Any]
    if isinstance(motions, Motion):
        items = [motions]
    elif isinstance(motions, np.ndarray) and motions.ndim == 2:
        items = [motions]
    else:
        items = list(motions)  # type: ignore[arg-type]
    if not items:
        raise ValueError("Expected at least one motion or path in `motions`, got none")
    ax = _new_axes(ax)
    for k, item in enumerate(items):
        xz, name = _ground_path(item, k)
        color = colors[k % len(colors)] if colors else COLORS[k % len(COLORS)]
        label = labels[k] if labels is not None else (name or f"path {k}")
        ax.plot(xz[:, 0], xz[:, 1], color=color, linewidth=linewidth, label=literal(label))
        ax.plot(*xz[0], "o", color=color, markersize=7)
        ax.plot(*xz[-1], "s", color=color, markersize=7)
        if ticks and isinstance(item, Motion):
            step = max(1, int(round(ticks * item.fps)))
            ax.plot(xz[::step, 0], xz[::step, 1], ".", color=color, markersize=5)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.set_title("root path, top view")
    _top_view(ax)
    ax.grid(True, alpha=0.3)
    if len(items) > 1 or labels is not None:
        ax.legend(loc="best", fontsize="small")
    return ax


# --------------------------------------------------------------------------
Component = Literal["angle", "x", "y", "z", "height", "speed"]


def joint_curves(
    motion: Motion,
    joints: str | Sequence[str],
    *,
    ax: Axes | None = None,
    component: Component = "height",
    contacts: Contacts | None = None,
    colors: Sequence[str] | None = None,
) -> Axes:
    """Per-joint curves over time.

    Parameters
    ----------
    motion : Motion
    joints : str or sequence of str
        Joint names.
    ax : Axes, optional
    component : {"angle", "x", "y", "z", "height", "speed"}
        ``"angle"``: angle of the joint's local rotation away from the rest
        pose, degrees; ``"x"``, ``"y"``, ``"z"``: world position, metres
        (``"height"`` is ``"y"``); ``"speed"``: world speed, m/s.
    contacts : Contacts, optional
        Shade the contact intervals of each plotted joint found in it.
    colors : sequence of str, optional

    Returns
    -------
    Axes
    """
    motion = _check_motion(motion)
    names = [joints] if isinstance(joints, str) else list(joints)
    if not names:
        raise ValueError("Expected at least one joint name in `joints`, got none")
    idx = [motion.skeleton.index(n) for n in names]
    if component == "angle":
        values = np.degrees(quat.angle(motion.rotations[:, idx]))
        unit = "local rotation angle (deg)"
    elif component in ("x", "y", "z", "height"):
        axis = {"x": 0, "y": 1, "height": 1, "z": 2}[component]
        values = motion.global_positions()[:, idx, axis]
        unit = "height y (m)" if axis == 1 else f"{component} (m)"
    elif component == "speed":
        values = motion.joint_speeds()[:, idx]
        unit = "speed (m/s)"
    else:
        raise ValueError(f"Expected `component` in ('angle', 'x', 'y', 'z', 'height', 'speed'), got {component!r}")
    if contacts is not None and contacts.n_frames != motion.n_frames:
        raise ValueError(f"Expected `contacts` over {motion.n_frames} frames, got {contacts.n_frames}")
    ax = _new_axes(ax, figsize=(8.0, 3.0))
    t = motion.times
    for k, name in enumerate(names):
        color = colors[k % len(colors)] if colors else COLORS[k % len(COLORS)]
        ax.plot(t, values[:, k], color=color, label=literal(name))
        if contacts is not None and name in contacts.joints:
            for a, b in contacts.intervals(name):
                ax.axvspan(a / motion.fps, (b - 1) / motion.fps, color=color, alpha=0.12, linewidth=0)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(unit)
    ax.set_xlim(t[0], t[-1] if t[-1] > t[0] else t[0] + 1.0)
    ax.legend(loc="best", fontsize="small")
    ax.grid(True, alpha=0.3)
    return ax


# --------------------------------------------------------------------------
def contact_timeline(
    contacts: Contacts,
    *,
    ax: Axes | None = None,
    colors: Sequence[str] | None = None,
    frame: int | None = None,
) -> Axes:
    """One row per joint, a bar over each contact interval, time in seconds.

    Parameters
    ----------
    contacts : Contacts
    ax : Axes, optional
    colors : sequence of str, optional
        Per joint; default: left-side joints blue, right-side joints orange,
        others grey (sides from the names' side words,
        :func:`mocaplab.roles.parse_name`).
    frame : int, optional
        Draw a vertical line at this frame.

    Returns
    -------
    Axes
    """
    if not isinstance(contacts, Contacts):
        raise TypeError(f"Expected `contacts` to be a Contacts, got {type(contacts).__name__}")
    ax = _new_axes(ax, figsize=(8.0, 0.5 + 0.4 * len(contacts.joints)))
    dt = 1.0 / contacts.fps
    for k, name in enumerate(contacts.joints):
        side = parse_name(name)[0]
        if colors:
            color = colors[k % len(colors)]
        elif side == "left":
            color = COLORS[0]
        elif side == "right":
            color = COLORS[1]
        else:
            color = COLORS[7]
        bars = [(a * dt, (b - a) * dt) for a, b in contacts.intervals(name)]
        ax.broken_barh(bars, (k - 0.35, 0.7), facecolors=color)
    if frame is not None:
        ax.axvline(int(frame) * dt, color="k", linewidth=1)
    ax.set_yticks(range(len(contacts.joints)), labels=[literal(j) for j in contacts.joints])
    ax.set_ylim(len(contacts.joints) - 0.5, -0.5)
    ax.set_xlim(0.0, max(contacts.n_frames * dt, dt))
    ax.set_xlabel("time (s)")
    ax.set_title("contacts")
    ax.grid(True, axis="x", alpha=0.3)
    return ax


# --------------------------------------------------------------------------
def balance_top(
    balance: Any,
    *,
    frames: Sequence[int] | None = None,
    ax: Axes | None = None,
    margin: float = 0.25,
    min_width: float = 1.0,
) -> Axes:
    """Support polygons, ZMP and the centre of mass's ground track, seen from above.

    Parameters
    ----------
    balance : mocaplab.physics.Balance
        The analysis to draw (its ``com``, ``zmp`` and ``polygon(frame)``).
    frames : sequence of int, optional
        Frames whose support polygons are drawn and whose ZMP is circled
        (default about twelve spread over the clip).
    ax : Axes, optional
    margin : float
        Metres of ground shown around the drawn points.
    min_width : float
        The across-travel extent shown is at least this many metres, so a
        straight walk is not drawn as a sliver.

    Returns
    -------
    Axes

    Notes
    -----
    Equal aspect.  The ground axis along which the clip travels furthest is
    horizontal; the view looks down from +Y as :func:`root_path` does (with
    ``x`` horizontal, ``z`` grows down the page; with ``z`` horizontal, ``x``
    grows up).  The legend sits outside the axes, to their right, never over
    the data.
    """
    for attr in ("com", "zmp", "polygon"):
        if not hasattr(balance, attr):
            raise TypeError(f"Expected `balance` to be a mocaplab.physics.Balance, got {type(balance).__name__}")
    com = np.asarray(balance.com, dtype=float)
    zmp = np.asarray(balance.zmp, dtype=float)
    n = len(com)
    frames = list(range(0, n, max(1, n // 12))) if frames is None else [int(f) for f in frames]
    for f in frames:
        if not 0 <= f < n:
            raise IndexError(f"Expected every frame of `frames` in [0, {n}), got {f}")
    ax = _new_axes(ax, figsize=(9.0, 3.5))
    span = np.ptp(com[:, [0, 2]], axis=0)
    h, v = (0, 2) if span[0] >= span[1] else (2, 0)
    shown = [com[:, [h, v]], zmp[:, [h, v]][np.all(np.isfinite(zmp), axis=1)]]
    for f in frames:
        poly = np.asarray(balance.polygon(f), dtype=float)
        if len(poly) >= 2:
            closed = np.vstack([poly, poly[:1]])
            ax.fill(closed[:, h], closed[:, v], color=COLORS[2], alpha=0.15, lw=0)
            ax.plot(closed[:, h], closed[:, v], color=COLORS[2], lw=0.8)
            shown.append(closed[:, [h, v]])
    ax.plot(com[:, h], com[:, v], color=COLORS[1], lw=1.2, label="centre of mass (ground track)")
    ax.plot(zmp[:, h], zmp[:, v], ".", color=COLORS[3], ms=3, label="ZMP")
    ax.plot(zmp[frames, h], zmp[frames, v], "o", mfc="none", color=COLORS[3], ms=6, label="ZMP at the drawn polygons")
    ax.fill([], [], color=COLORS[2], alpha=0.3, label="support polygon")
    pts = np.concatenate(shown)
    lo, hi = pts.min(axis=0) - margin, pts.max(axis=0) + margin
    mid, half = 0.5 * (lo[1] + hi[1]), max(0.5 * (hi[1] - lo[1]), 0.5 * min_width)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(mid - half, mid + half)
    ax.set_aspect("equal", adjustable="box")
    if h == 0:
        _top_view(ax)
    ax.set_xlabel(f"{_AXIS_NAMES[h]} (m)")
    ax.set_ylabel(f"{_AXIS_NAMES[v]} (m)")
    ax.set_title("Support polygons at the circled frames, seen from above")
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, fontsize="small")
    ax.grid(True, alpha=0.3)
    return ax


__all__ += ["balance_top"]


# --------------------------------------------------------------------------
def path_vectors(
    path: Any,
    *,
    ax: Axes | None = None,
    frames: Sequence[int] | None = None,
    every: int = 8,
    tangents: bool = True,
    normals: bool = True,
    headings: bool = False,
    length: float | None = None,
    color: str = "0.6",
    label: str | None = None,
) -> Axes:
    """Top view of a motion path with its tangents, normals and headings as arrows.

    Tangents are black, normals (the character's left, ``R t``) crimson,
    headings (where the pelvis faces) in the path's ``color`` if it is not
    grey, else green.  Degenerate frames (:attr:`MotionPath.degenerate`) are
    marked with a cross.  Same top view as :func:`root_path`.

    Parameters
    ----------
    path : MotionPath
        From :meth:`mocaplab.editing.MotionPath.from_motion`.
    ax : Axes, optional
    frames : sequence of int, optional
        Frames that get arrows (default every ``every``-th frame).
    every : int
        Spacing of the arrows when ``frames`` is not given.
    tangents, normals, headings : bool
        Which arrows to draw.
    length : float, optional
        Draw unit arrows this long (metres).  Default: tangents and normals
        at three times their size (a central difference spans two frames,
        a few centimetres), headings 0.25 m.
    color : str
        Colour of the path line.
    label : str, optional
        Legend label of the path line.

    Returns
    -------
    Axes
    """
    from .editing.paths import MotionPath

    if not isinstance(path, MotionPath):
        raise TypeError(f"Expected `path` to be a MotionPath, got {type(path).__name__}")
    if frames is None:
        if int(every) < 1:
            raise ValueError(f"Expected `every` >= 1, got {every!r}")
        idx = np.arange(0, path.n_frames, int(every))
    else:
        idx = np.asarray(frames, dtype=np.int64).reshape(-1)
        if idx.size and not (-path.n_frames <= idx.min() and idx.max() < path.n_frames):
            raise IndexError(f"Expected `frames` in [0, {path.n_frames}), got {idx.tolist()}")
    ax = _new_axes(ax, figsize=(6.0, 5.0))
    p = np.asarray(path.positions)
    ax.plot(p[:, 0], p[:, 1], color=color, label=literal(label))
    if path.degenerate.any():
        ax.plot(*p[path.degenerate].T, "x", color="crimson", label="degenerate")
    at = p[idx]

    def arrows(v: NDArray[np.float64], c: str, default: float | None) -> None:
        size = length if length is not None else default
        if size is not None:
            n = np.linalg.norm(v, axis=1, keepdims=True)
            v = v / np.where(n > 0, n, 1.0) * size
        else:
            v = 3.0 * v
        ax.quiver(at[:, 0], at[:, 1], v[:, 0], v[:, 1], angles="xy", scale_units="xy", scale=1.0, color=c, width=0.004)

    if tangents:
        arrows(np.asarray(path.tangents)[idx], "k", None)
    if normals:
        arrows(np.asarray(path.normals)[idx], "crimson", None)
    if headings:
        h = np.asarray(path.headings)[idx]
        arrows(np.c_[np.sin(h), np.cos(h)], "green" if color == "0.6" else color, 0.25)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    _top_view(ax)
    ax.grid(True, alpha=0.3)
    return ax


def time_warps(
    warps: Sequence[Any],
    labels: Sequence[str],
    *,
    h: float,
    character: int = 0,
    axes: Sequence[Axes] | None = None,
    title: str = "",
) -> tuple[Axes, Axes]:
    """Time warps side by side: reference time per frame, and the step per frame in units of ``h``.

    Parameters
    ----------
    warps : sequence of EditResult or array_like
        Each an edit result (its ``times[character]`` is drawn) or an array
        of reference times, one per frame, shape (F,).
    labels : sequence of str
        One per warp.
    h : float
        The clip's frame time (seconds): the unedited step.
    character : int
        Which character of the edit results.
    axes : pair of Axes, optional
        Where to draw (default: a new figure with two panels).
    title : str

    Returns
    -------
    (Axes, Axes)
    """
    if len(labels) != len(warps):
        raise ValueError(f"Expected one label per warp ({len(warps)}), got {len(labels)}")
    if not (np.isfinite(h) and h > 0):
        raise ValueError(f"Expected `h` > 0 seconds, got {h!r}")
    fig: Any
    if axes is None:
        import matplotlib.pyplot as plt

        fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.5), layout="constrained")
    else:
        a1, a2 = axes
        fig = a1.figure
    for k, (w, label) in enumerate(zip(warps, labels, strict=True)):
        t = np.asarray(w.times[character] if hasattr(w, "times") else w, dtype=float)
        if t.ndim != 1:
            raise ValueError(f"Expected warp {k} as an edit result or times of shape (F,), got shape {t.shape}")
        a1.plot(t, label=literal(label))
        a2.plot(np.diff(t) / h, label=literal(label))
    a2.axhline(0.0, color="0.5", linewidth=0.8)
    a1.set_xlabel("frame i")
    a1.set_ylabel("reference time t_i (s)")
    a2.set_xlabel("frame i")
    a2.set_ylabel("step (t[i+1] - t[i]) / h")
    a1.legend(fontsize="small")
    a1.grid(True, alpha=0.3)
    a2.grid(True, alpha=0.3)
    if title:
        fig.suptitle(literal(title))
    return a1, a2


__all__ += ["path_vectors", "time_warps"]
