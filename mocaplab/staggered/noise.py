"""Filtering rotations before timing edits (Coleman et al. 2008, section 6).

Section 6: "When applying temporal edits to recorded human motion, care must
be taken [...] to avoid artifacts associated with correlated noise in
sequential joints.  [...] these will correlate with child joints to
approximately cancel out on descendent joints [...].  De-correlating these
signals in time removes this cancelation, and short high-frequency artifacts
can appear in descendent joints.  Appropriate filtering of rotation data
before editing avoids this problem [LS02]."

Measured on the CMU walk 16_15: whole-body succession (``s = 0.03``,
``l = 2``) on the unfiltered clip raised the head's jitter (:func:`jitter`)
from 0.53 to 2.71 mm, 5.1 times the capture's.

What mocaplab does (``extract(..., filter_sigma=...)``, on by default):

1. **Filter** every joint rotation with :func:`orientation_filter`, Lee and
   Shin's (2002) construction of a time-domain filter for orientation data
   from a linear mask, here a Gaussian of ``filter_sigma`` seconds
   (:data:`FILTER_SIGMA`, 0.03 s): the angular displacements between
   consecutive frames are filtered, so the filter is coordinate-invariant
   and its output stays on the rotation group.
2. **Fit** the staggered poses, splines and displacement maps to the
   filtered rotations: everything that timing edits move is smooth.
3. **Keep** what the filter removed, ``log(q_filtered^-1 q)``, less its
   sharp motions (below), as a *noise layer* applied last,
   ``v_i(t) = s_i(t') (+) d_i(t') (+) h_i(t') (+) n_i(u(t))``,
   on the pose timing ``u(t)`` shared by every joint (the position of ``t``
   between pose times, as for the constraint layer).  So the unedited clip is
   still reproduced exactly, a retimed pose carries its noise along, and the
   noise of sequential joints stays as correlated as captured, cancelling on
   their descendants: succession and random timing no longer pull it apart.

A sharp motion is not noise.  A kick's flick, a foot slapping down or an
arm's snap turns a joint faster than the filter's band (above about 4 Hz),
so part of the motion itself lands in the residual; held on the shared pose
timing it stayed put while the rest of the joint moved, and a succession on
a flick showed it twice (the foot of the broad jump 16_05 at its landing:
669 deg/s at the original time and 464 deg/s 100 ms later, against 1103
deg/s once in the capture).  :func:`sharp_detail` takes the part of each
joint's residual that reaches the ends of its subtree (capture noise of
sequential joints cancels there, a motion does not), wherever its local RMS
passes :data:`SHARP_ANGLES` (2 to 4 degrees), and the fit keeps it as the
*sharp layer* ``h_i``, sampled like the displacement maps on the variable's
own normalised time ``t'``, so it moves with the joint's own knots; the
noise layer keeps the rest.  Geometric edits leave it alone, as they leave
the displacement maps (fitting the splines to it instead let an exaggeration
scale a flick caught on a knot: the salsa's left foot at 4 times the input's
angular acceleration under the constraint layer).  The flick then happens
once, at its new time (1082 deg/s 100 ms later), and the glitches that
sequential joints cancel (16_11: the pelvis, hips and lower back turning 10
degrees and back in a few frames) stay together, as does the dance 05_02's
twist of the upper arm by 31 degrees that the hand takes back.  On the walk
16_15 the sharp part is 4 % of the joints' frames (toes, fingers, the feet
at heel strike) and the head's jitter after the succession below is
unchanged.

The root and joint translations are not filtered (the paper speaks of
rotations; their capture noise does not compound down a chain).

With the default, the head's jitter after that succession is 0.62 mm, 1.17
times the capture's (``tests/test_staggered_noise.py`` holds it under 1.5);
a mild whole-body succession (``s = 0.01``, ``l = 1``) went from 4.7 times
to 1.01 times.  Smaller sigmas leave more high frequency in the retimed
layers (0.017 s: 1.96 times, 0.025 s: 1.33 times); larger ones put more of
the motion on the shared timing (the noise layer's RMS angle over the
joints of 16_15 is 0.94 degrees at 0.017 s, 1.25 at 0.03 s, 1.46 at 0.04 s).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import correlate1d

from .. import quat
from ..displacement import blend_ramp
from ..kinematics import fk
from ..motion import Motion, Skeleton
from .features import check_rates

__all__ = ["FILTER_SIGMA", "SHARP_ANGLES", "orientation_filter", "filter_mask", "sharp_detail", "jitter"]

Array = NDArray[np.float64]

FILTER_SIGMA = 0.03
"""Default Gaussian sigma of the rotation filter, seconds (3.6 frames at 120 fps)."""


def filter_mask(sigma: float, fps: float) -> Array:
    """The Gaussian mask ``a_k``, ``k = -n .. n`` (``n = ceil(3 sigma fps)``), summing to 1, shape (2n + 1,)."""
    s = float(sigma) * float(fps)
    n = max(1, int(np.ceil(3.0 * s)))
    a = np.exp(-0.5 * (np.arange(-n, n + 1) / s) ** 2)
    return a / a.sum()


def orientation_filter(rotations: ArrayLike, sigma: float, fps: float) -> Array:
    """Low-pass filter unit quaternions along axis 0 (Lee and Shin 2002).

    For a linear mask ``a_k`` (here Gaussian, :func:`filter_mask`) the
    orientation filter is

        H(q)_i = q_i exp(sum_{k=-n}^{n-1} b_k w_{i+k}),
        b_k = sum_{j > k} a_j (k >= 0),  b_k = -sum_{j <= k} a_j (k < 0),

    with the angular displacements ``w_i = log(q_i^-1 q_{i+1})`` (body
    frame): the mask applied to the rotation vectors of ``q_i^-1 q_{i+k}``,
    each taken as the sum of the displacements in between.  Beyond the clip's
    ends the orientation is held (``w = 0``).

    Parameters
    ----------
    rotations : array_like, shape (F, ...,  4)
        Unit quaternions, frames first.
    sigma : float
        Gaussian sigma, seconds (0 returns a copy), at most
        :data:`~mocaplab.staggered.features.MAX_FILTER_SECONDS`.
    fps : float
        At most :data:`~mocaplab.staggered.features.MAX_FPS`.

    Returns
    -------
    ndarray, shape (F, ..., 4)
        Unit quaternions in the hemispheres of the inputs.  A constant
        rotation is returned exactly.

    Examples
    --------
    >>> import numpy as np
    >>> from mocaplab import quat
    >>> t = np.arange(120) / 120.0
    >>> q = quat.from_axis_angle([0, 0, 1], 0.5 * t + 0.01 * np.sin(2 * np.pi * 40 * t))  # a turn plus a 40 Hz buzz
    >>> smooth = orientation_filter(q, 0.03, 120.0)
    >>> bool(np.abs(quat.angle(quat.mul(quat.inv(smooth), q)))[20:-20].max() < 0.011)
    True
    """
    q = np.asarray(rotations, dtype=float)
    if q.ndim < 2 or q.shape[-1] != 4:
        raise ValueError(f"Expected `rotations` of shape (F, ..., 4), got {q.shape}")
    if not (np.isfinite(sigma) and sigma >= 0):
        raise ValueError(f"Expected `sigma` >= 0 seconds, got {sigma!r}")
    check_rates(float(fps), sigma=float(sigma))  # the mask has 6 sigma fps + 1 taps: bounded before it is built
    if sigma == 0 or q.shape[0] < 2:
        return np.array(q, copy=True)
    a = filter_mask(sigma, fps)
    n = (a.size - 1) // 2
    q = quat.unroll(q, axis=0)
    w = quat.log(quat.mul(quat.inv(q[:-1]), q[1:]))  # (F - 1, ..., 3): w_i between frames i and i + 1
    tail = np.cumsum(a[::-1])[::-1]  # tail[j] = sum_{j' >= j} a_j'
    k = np.arange(-n, n)  # offsets of w_{i+k}
    b = np.where(k >= 0, tail[np.clip(k + n + 1, 0, 2 * n)], -(1.0 - tail[np.clip(k + n + 1, 0, 2 * n)]))
    # sum_k b_k w_{i+k} for every frame i: a correlation of w with b, w = 0 outside [0, F - 2]
    F = q.shape[0]
    padded = np.zeros((F + 2 * n,) + w.shape[1:])
    padded[n : n + F - 1] = w
    # out[i] = sum_k b_k padded[i + n + k]: a correlation with weights centred on k = 0
    weights = np.concatenate([b, [0.0]])  # offsets -n .. n (k = n has no displacement)
    flat = padded.reshape(padded.shape[0], -1)
    out = correlate1d(flat, weights, axis=0, mode="constant", cval=0.0)[n : n + F]
    delta = out.reshape((F,) + w.shape[1:])
    smooth = quat.mul(q, quat.exp(delta))
    return np.where(np.sum(smooth * q, axis=-1, keepdims=True) < 0, -smooth, smooth)


SHARP_ANGLES = (np.deg2rad(2.0), np.deg2rad(4.0))
"""Local RMS of the residual that reaches a joint's end effectors, radians: below the first, capture noise
(kept on the pose timing); above the second, a sharp motion (retimed with the joint's knots); a
:func:`~mocaplab.displacement.blend_ramp` in between (:func:`sharp_detail`)."""


def sharp_detail(
    captured: ArrayLike,
    filtered: ArrayLike,
    skeleton: Skeleton,
    fps: float,
    *,
    sigma: float = FILTER_SIGMA,
    angles: tuple[float, float] = SHARP_ANGLES,
) -> Array:
    """The part of the filtered-out residual that is motion, not capture noise (issue 25 item 3).

    The residual ``n = log(filtered^-1 captured)`` of a joint holds capture
    noise and, where the joint moves faster than the filter's band (a
    kick's flick, a foot slapping down), part of the motion itself.  Noise
    of sequential joints cancels on their descendants (section 6), motion
    does not, so a joint's residual counts as sharp as far as it reaches the
    ends of its subtree:

    1. ``N_c``: the angle between the captured and the filtered *global*
       orientation of every joint ``c`` (forward kinematics of each);
    2. ``a_j = min(|n_j|, max_c N_c)`` over the joints ``c`` without
       children in the subtree of ``j`` (its end effectors: toes, fingers,
       the head; ``j`` itself if it has no children);
    3. its local RMS over a Gaussian of ``sigma`` seconds, ``e_j``, gives the
       weight ``g_j = blend_ramp((e_j - lo) / (hi - lo))`` with
       ``(lo, hi) = angles``;
    4. the sharp detail is ``g_j n_j``, faded in and out with a
       :func:`~mocaplab.displacement.blend_ramp` over the mask's half-width
       (3 sigma) at the clip's ends, where the residual is the filter's end
       condition (the orientation held beyond them) as much as motion, and
       where the first and last poses never move.  (The CMU run 09_06 ends on
       finger jitter of 10 to 16 degrees; carried with the fingers' knots
       into a last segment a strong arm succession squeezes, it doubled
       their angular acceleration.)

    :func:`~mocaplab.staggered.fit_representation` keeps it as the sharp
    layer, which moves with each variable's knots, and leaves the rest on
    the shared pose timing: under a succession the flick
    happens once, at its joint's new time, while glitches that sequential
    joints cancel stay together.

    Parameters
    ----------
    captured, filtered : array_like, shape (F, J, 4)
        Local joint rotations before and after :func:`orientation_filter`
        (same hemispheres).
    skeleton : Skeleton
        Gives the joint hierarchy.
    fps : float
        Frame rate, frames per second.
    sigma : float, default :data:`FILTER_SIGMA`
        Width of the local RMS, seconds.
    angles : (float, float), default :data:`SHARP_ANGLES`
        Where the weight starts to rise and where it reaches 1, radians.

    Returns
    -------
    ndarray, shape (F, J, 3)
        Rotation vectors, exactly 0 where the weight is 0.

    Examples
    --------
    At 0.5 s the knee flicks 40 degrees, which reaches the foot; at frame 20
    the hip jolts 11 degrees and the knee takes it back, which does not:

    >>> import numpy as np
    >>> from mocaplab import quat
    >>> from mocaplab.motion import Skeleton
    >>> sk = Skeleton(["hip", "knee", "foot"], [-1, 0, 1], [[0, 1, 0], [0, -0.5, 0], [0, -0.5, 0]])
    >>> t = np.arange(120) / 120.0
    >>> q = np.tile([0.0, 0.0, 0.0, 1.0], (120, 3, 1))
    >>> q[:, 1] = quat.from_axis_angle([1, 0, 0], np.radians(40) * np.exp(-0.5 * ((t - 0.5) / 0.01) ** 2))
    >>> q[20, 0], q[20, 1] = quat.from_axis_angle([1, 0, 0], 0.2), quat.from_axis_angle([1, 0, 0], -0.2)
    >>> smooth = orientation_filter(q, 0.03, 120.0)
    >>> np.degrees(quat.angle(quat.mul(quat.inv(smooth), q))[[20, 60]]).round(1).tolist()  # hip, knee, foot
    [[10.2, 10.2, 0.0], [0.0, 27.3, 0.0]]
    >>> d = sharp_detail(q, smooth, sk, 120.0)
    >>> np.degrees(np.linalg.norm(d[[20, 60]], axis=-1)).round(1).tolist()
    [[0.0, 0.0, 0.0], [0.0, 27.3, 0.0]]
    """
    q = np.asarray(captured, dtype=float)
    qf = np.asarray(filtered, dtype=float)
    if q.shape != qf.shape or q.ndim != 3 or q.shape[1:] != (skeleton.n_joints, 4):
        raise ValueError(
            f"Expected `captured` and `filtered` of shape (F, {skeleton.n_joints}, 4), got {q.shape} and {qf.shape}"
        )
    lo, hi = (float(a) for a in angles)
    if not (np.isfinite(lo) and np.isfinite(hi) and 0.0 <= lo < hi):
        raise ValueError(f"Expected `angles` (lo, hi) with 0 <= lo < hi radians, got {angles!r}")
    n = quat.log(quat.mul(quat.inv(qf), q))
    if q.shape[0] < 2:
        return np.zeros_like(n)
    zero = np.zeros((q.shape[0], 3))
    g_cap = fk(q, zero, skeleton.offsets, skeleton.parents)[0]
    g_fil = fk(qf, zero, skeleton.offsets, skeleton.parents)[0]
    N = quat.angle(quat.mul(quat.inv(g_fil), g_cap))  # (F, J) residual of the global orientations
    parents = np.asarray(skeleton.parents)
    leaf = np.ones(skeleton.n_joints, dtype=bool)
    leaf[parents[1:]] = False
    reach = np.where(leaf, N, 0.0)  # the largest residual at the ends of each joint's subtree
    for c in range(skeleton.n_joints - 1, 0, -1):  # children before parents (parents[c] < c), every frame at once
        reach[:, parents[c]] = np.maximum(reach[:, parents[c]], reach[:, c])
    a = np.minimum(np.linalg.norm(n, axis=-1), reach)
    mask = filter_mask(sigma, fps)
    e = np.sqrt(np.maximum(correlate1d(a * a, mask, axis=0, mode="nearest"), 0.0))
    g = blend_ramp((e - lo) / (hi - lo))
    # near the clip's ends the residual is the filter's end condition (the orientation held beyond them) as much
    # as motion, and the first and last poses never move: the weight fades in over the mask's half-width
    half = (mask.size - 1) // 2
    edge = np.minimum(np.arange(q.shape[0]), np.arange(q.shape[0])[::-1])
    g = g * blend_ramp(edge / half)[:, None]
    return np.where(g[..., None] > 0.0, g[..., None] * n, 0.0)


def jitter(motion: Motion, joint: str | int, *, sigma: float = 2.0, trim: int = 5) -> float:
    """High-frequency content of a joint's world path: RMS distance from its Gaussian-smoothed path, metres.

    ``sigma`` is in frames (2 frames at 120 fps: what remains is above about
    8 Hz); ``trim`` frames at each end are left out.  The capture of the CMU
    walk 16_15 has a head jitter of 0.53 mm.

    Parameters
    ----------
    motion : Motion
    joint : str or int
        Joint name or index.
    sigma : float, default 2.0
        Gaussian smoothing sigma, frames.
    trim : int, default 5
        Frames left out at each end (where the smoothing sees the clip's edge).

    Returns
    -------
    float
        Metres.

    Examples
    --------
    >>> import mocaplab as ml
    >>> round(ml.staggered.jitter(ml.cmu("16_15"), "Head") * 1000, 2)   # millimetres
    0.53
    """
    from scipy.ndimage import gaussian_filter1d

    j = motion.skeleton.index(joint) if isinstance(joint, str) else int(joint)
    p = motion.global_positions()[:, j]
    hf = p - gaussian_filter1d(p, float(sigma), axis=0, mode="nearest")
    if hf.shape[0] > 2 * trim:
        hf = hf[trim : hf.shape[0] - trim]
    return float(np.sqrt(np.mean(np.sum(hf * hf, axis=-1))))
