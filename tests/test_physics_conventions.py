"""The body model, the balance analysis and the touch-up under every file convention.

Each CMU clip (16_15, a walk; 16_05, a jump) is written in every convention
of ``tests/conventions.py``, read back with :func:`mocaplab.load` and run
with **no joint name passed**: :meth:`Body.from_skeleton`, the centre of
mass, the ZMP, the support polygon, :func:`fit_masses` and a short default
:func:`touch_up` must give the CMU original's answers.  Tolerances, in
:data:`TOL` (measured maxima over both clips in brackets):

* conventions that only re-express the input (names, a static root, units,
  Euler orders, axes, frame rate): 1 mm everywhere, 0.1 % on fitted masses
  (file precision is micrometres);
* ``zero_end_sites`` removes the end sites, so the top of the head and the
  toe tips are estimated (:data:`mocaplab.anatomy.HEAD_TOP`,
  :data:`~mocaplab.anatomy.TOE_TIP`): the head link within 4 mm
  [3.2] and the support points within 8 mm [7.6] (the estimates'
  documented accuracy on CMU); the centre of mass [0.22] and the ZMP
  [0.31] still within 1 mm;
* ``x_bones`` removes the rest pose (a zig-zag, the rest rotations baked
  into the motion), so the body is measured in
  :func:`mocaplab.physics.standing_pose` of the motion instead (with a
  :class:`~mocaplab.physics.RestPoseWarning`).  What the CMU rest pose
  fixes arbitrarily cannot come back from such a file: the CMU rest neck is
  not straight (its bones turn by some 18 degrees), so the head link
  differs by up to 12 mm [9.4], which moves the centre of mass by under
  1 mm [0.66] and the ZMP by under 1.5 mm [0.98]; every other link agrees
  within 1 mm [0.0].  The CMU rest pose holds the feet rolled 15-25
  degrees from a foot planted flat, so its heel and side support points
  tilt with the foot where the standing pose has them level: within 3 cm
  [2.7].  (Measured in the zig-zag rest pose instead, the pelvis link is
  7 cm off and the centre of mass 4 mm: tested below.)
* The ZMP distance to the support polygon moves by no more than the ZMP
  plus the farthest-moving planted support point (it is 1-Lipschitz in the
  query point, and the convex hulls of points moved by at most ``e`` lie
  within ``e`` of each other): checked frame by frame; besides, per frame
  within 8 mm [5.2] (``zero_end_sites``) and 12 mm [9.4] (``x_bones``, on
  the few frames where the ZMP lies off a heel or a toe's side), and on
  average within 1.5 mm [0.81, 0.95].
* ``fit_masses`` and ``touch_up`` inherit these differences: the mean
  distance before and after the fit, and the touch-up's error per step,
  within 1.5 mm [0.95]; the fitted masses within 15 % [11.3], for they are
  weakly determined (equation 5 is flat near its minimum and held by a weak
  pull towards the table, so the 6-7 % change of the objective that the
  moved support points make on 16_15 moves them by that much); the
  touched-up joints within 4 mm [2.7] (``zero_end_sites``) and 6 mm [4.9]
  (``x_bones``: frames out of reach of the closed form take their
  closest-approach rotation, which follows the ZMP's small differences),
  while the touch-up moves the originals' joints by 12-20 mm.

CMU's own answers are those of the rest pose: a standing rest pose is used
as it is (the default body is ``pose="rest"``'s, bit for bit).
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
from conventions import CONVENTIONS, as_original

from mocaplab import edit, quat, refine
from mocaplab.contacts import foot_contacts
from mocaplab.editing import PinPosition
from mocaplab.physics import (
    Body,
    RestPoseWarning,
    balance,
    center_of_mass,
    fit_masses,
    link_positions,
    signed_distance,
    standing_pose,
    touch_up,
)

CLIPS = ("16_15", "16_05")
FRAMES = slice(0, 360)
MM = 1e-3

#: Per convention: link centres (head link apart), head link, centre of
#: mass, ZMP, support points, ZMP distance (per frame, mean), touched-up
#: joints, metres; fitted masses, relative.  See the module docstring.
EXACT = dict(link=1 * MM, head=1 * MM, com=1 * MM, zmp=1 * MM, support=1 * MM, dist=1 * MM, mean=1 * MM, touch=1 * MM, mass=1e-3)
TOL = {c: EXACT for c in CONVENTIONS}
TOL["zero_end_sites"] = {
    **EXACT, "head": 4 * MM, "support": 8 * MM, "dist": 8 * MM, "mean": 1.5 * MM, "touch": 4 * MM, "mass": 0.15,
}
TOL["x_bones"] = {
    **EXACT, "head": 12 * MM, "zmp": 1.5 * MM, "support": 30 * MM, "dist": 12 * MM, "mean": 1.5 * MM, "touch": 6 * MM,
    "mass": 0.15,
}


def _original(cmu, clip, convention):
    return as_original(cmu(clip)[FRAMES], convention)


@pytest.fixture(scope="module")
def converted(converted):
    """The shared ``converted`` fixture (tests/conftest.py) on this module's frames."""
    return lambda clip, convention: converted(clip, convention, FRAMES)


@pytest.fixture(scope="module")
def reference(cmu):
    """The CMU original's body, balance and touch-up (cached per clip and frame rate)."""
    cache: dict = {}

    def get(clip: str, convention: str):
        key = (clip, convention == "fps30")
        if key not in cache:
            m = _original(cmu, clip, convention)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # touch-up notes about the input
                cache[key] = (m, Body.from_skeleton(m), balance(m), touch_up(m, iterations=1))
        return cache[key]

    return get


def _body(motion, convention):
    """The default body, checking that only a rest pose that does not stand warns."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        body = Body.from_skeleton(motion)
    notes = [w for w in caught if issubclass(w.category, RestPoseWarning)]
    assert bool(notes) == (convention == "x_bones"), [str(w.message) for w in notes]
    if notes:
        assert "not a standing pose" in str(notes[0].message) and "standing_pose" in str(notes[0].message)
    return body


def _columns(motion, name_map, names):
    return [motion.skeleton.index(name_map[n]) for n in names]


@pytest.mark.parametrize("convention", CONVENTIONS)
@pytest.mark.parametrize("clip", CLIPS)
def test_body_links_masses_and_centre_of_mass(converted, reference, clip, convention):
    m, name_map = converted(clip, convention)
    ref, body0, _, _ = reference(clip, convention)
    tol = TOL[convention]
    body = _body(m, convention)
    assert body.link_names == body0.link_names
    np.testing.assert_allclose(body.masses, body0.masses, rtol=1e-12)
    owners = [m.skeleton.names[j] for j in body.owners]
    assert owners == [name_map[ref.skeleton.names[j]] for j in body0.owners]
    err = np.abs(link_positions(m, body) - link_positions(ref, body0)).max(axis=(0, 2))
    head = body.link_index("head")
    assert err[head] < tol["head"], err[head]
    assert np.delete(err, head).max() < tol["link"], dict(zip(body.link_names, err, strict=True))
    com = np.abs(center_of_mass(m, body) - center_of_mass(ref, body0)).max()
    assert com < tol["com"], com


@pytest.mark.parametrize("convention", CONVENTIONS)
@pytest.mark.parametrize("clip", CLIPS)
def test_zmp_support_polygon_and_distance(converted, reference, clip, convention):
    m, name_map = converted(clip, convention)
    ref, _, bal0, _ = reference(clip, convention)
    tol = TOL[convention]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RestPoseWarning)
        bal = balance(m)
    np.testing.assert_array_equal(bal.ground, bal0.ground)
    np.testing.assert_array_equal(bal.active, bal0.active)
    np.testing.assert_array_equal(np.isnan(bal.zmp), np.isnan(bal0.zmp))
    zmp = np.linalg.norm(bal.zmp - bal0.zmp, axis=-1)
    assert np.nanmax(zmp) < tol["zmp"], np.nanmax(zmp)
    moved = np.linalg.norm(bal.support - bal0.support, axis=-1)
    assert moved.max() < tol["support"], moved.max()
    np.testing.assert_array_equal(np.isnan(bal.distance), np.isnan(bal0.distance))
    dist = np.abs(bal.distance - bal0.distance)
    # the distance moves by no more than the ZMP and the farthest support point moved
    ok = np.isfinite(dist)
    bound = zmp + np.where(bal.active, moved, 0.0).max(axis=1)
    assert np.all(dist[ok] <= bound[ok] + 1e-9)
    assert dist[ok].max() < tol["dist"], dist[ok].max()
    assert abs(bal.mean_distance - bal0.mean_distance) < tol["mean"]
    # one polygon through ConvexHull, where the ZMP is farthest off: each
    # vertex of one lies within the support tolerance of the other
    frame = int(np.nanargmax(np.where(bal0.ground, bal0.distance, np.nan)))
    a, b = bal.polygon(frame)[:, [0, 2]], bal0.polygon(frame)[:, [0, 2]]
    assert len(a) >= 3 and len(b) >= 3
    for p, other in [(p, b) for p in a] + [(p, a) for p in b]:
        assert signed_distance(p, other) < tol["support"]


@pytest.mark.parametrize("convention", CONVENTIONS)
@pytest.mark.parametrize("clip", CLIPS)
def test_fitted_masses(converted, reference, clip, convention):
    m, _ = converted(clip, convention)
    ref, _, _, _ = reference(clip, convention)
    tol = TOL[convention]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RestPoseWarning)
        fit = fit_masses(m, max_iterations=30)
    fit0 = fit_masses(ref, max_iterations=30)
    assert fit.body.link_names == fit0.body.link_names
    assert abs(fit.before - fit0.before) < tol["mean"] and abs(fit.after - fit0.after) < tol["mean"]
    assert fit.after < fit.before
    np.testing.assert_allclose(fit.body.masses, fit0.body.masses, rtol=tol["mass"])


@pytest.mark.parametrize("convention", CONVENTIONS)
@pytest.mark.parametrize("clip", CLIPS)
def test_default_touch_up(converted, reference, clip, convention):
    m, name_map = converted(clip, convention)
    ref, _, _, hist0 = reference(clip, convention)
    tol = TOL[convention]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the rest pose, touch-up notes about the input
        hist = touch_up(m, iterations=1)
    assert hist.labels == hist0.labels and hist.best == hist0.best and hist.stopped == hist0.stopped
    np.testing.assert_array_equal(hist.dropped, hist0.dropped)
    assert np.abs(hist.errors - hist0.errors).max() < tol["mean"]
    cols = _columns(m, name_map, ref.skeleton.names)
    moved = np.abs(hist.motion.global_positions()[:, cols] - hist0.motion.global_positions()).max()
    assert moved < tol["touch"], moved
    # and the touch-up did something on the original (so agreeing is not trivial)
    assert np.abs(hist0.motion.global_positions() - ref.global_positions()).max() > 2 * tol["touch"]


@pytest.mark.parametrize("clip", CLIPS)
def test_a_standing_rest_pose_is_kept_bit_for_bit(cmu, clip):
    walk = cmu(clip)[FRAMES]
    with warnings.catch_warnings():
        warnings.simplefilter("error", RestPoseWarning)
        body = Body.from_skeleton(walk)
    rest = Body.from_skeleton(walk, pose="rest")
    for name in ("offsets", "point_offsets", "masses", "owners", "point_owners"):
        np.testing.assert_array_equal(getattr(body, name), getattr(rest, name))
    # a standing pose of the motion is another body (so the rest pose is really what was used)
    other = Body.from_skeleton(walk, pose=standing_pose(walk))
    assert np.abs(other.offsets - body.offsets).max() > 1 * MM


@pytest.mark.parametrize("clip", CLIPS)
def test_the_standing_pose_is_the_same_pose_in_either_skeleton(converted, cmu, clip):
    """Measured in standing_pose, the x_bones skeleton and the CMU original have one body (file precision)."""
    m, name_map = converted(clip, "x_bones")
    ref = cmu(clip)[FRAMES]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RestPoseWarning)
        body = Body.from_skeleton(m)
    same = Body.from_skeleton(ref, pose=standing_pose(ref))
    assert np.abs(link_positions(m, body) - link_positions(ref, same)).max() < 0.05 * MM
    feet = sorted(set(body.point_joints))
    assert feet == sorted(name_map[n] for n in set(same.point_joints))
    pts, _ = body.support_points(m, feet)
    pts0, _ = same.support_points(ref, feet)
    assert np.abs(pts - pts0).max() < 0.05 * MM


@pytest.mark.parametrize("clip", CLIPS)
def test_the_degenerate_rest_pose_is_far_off(converted, reference, clip):
    """What the standing pose repairs: measured in the zig-zag rest pose, links are centimetres off."""
    m, _ = converted(clip, "x_bones")
    ref, body0, bal0, _ = reference(clip, "x_bones")
    body = Body.from_skeleton(m, pose="rest")
    err = np.abs(link_positions(m, body) - link_positions(ref, body0)).max(axis=(0, 2))
    assert err[body.link_index("pelvis")] > 5 * 10 * MM
    com = np.abs(center_of_mass(m, body) - center_of_mass(ref, body0)).max()
    assert com > 3 * TOL["x_bones"]["com"]
    # the mean pose without straight chains puts the head link off by centimetres
    q = np.asarray(m.rotations)
    mean = np.linalg.eigh(np.einsum("fji,fjk->jik", q, q))[1][..., -1]
    bent = Body.from_skeleton(m, pose=mean)
    err = np.abs(link_positions(m, bent) - link_positions(ref, body0)).max(axis=(0, 2))
    assert err[bent.link_index("head")] > 1.5 * TOL["x_bones"]["head"]


def test_the_standing_pose_does_not_depend_on_the_heading(cmu):
    """A clip turned about the vertical, a full turn over its length, has the same standing pose."""
    walk = cmu("16_15")[FRAMES]
    turn = quat.from_yaw(np.linspace(0.0, 2.0 * np.pi, walk.n_frames))
    spun = walk.with_root(
        root_positions=quat.rotate(turn, walk.root_positions), root_rotations=quat.mul(turn, walk.rotations[:, 0])
    )
    a, b = standing_pose(walk), standing_pose(spun)
    assert np.abs(np.abs(np.einsum("ji,ji->j", a, b)) - 1.0).max() < 1e-9  # q and -q are one rotation


def test_one_bone_links_and_end_sites_do_not_depend_on_the_pose(cmu):
    """Measured in any pose, a link along one bone and a point on an end site are where the rest pose has them."""
    walk = cmu("16_15")[FRAMES]
    rest = Body.from_skeleton(walk)
    posed = Body.from_skeleton(walk, pose=walk.rotations[100])
    multi = {"pelvis", "head", "left_hand", "right_hand"}  # across helpers, the neck, the fingers
    for k, name in enumerate(rest.link_names):
        if name not in multi:
            np.testing.assert_allclose(posed.offsets[k], rest.offsets[k], atol=1e-12, err_msg=name)
    assert np.abs(posed.offsets[rest.link_index("head")] - rest.offsets[rest.link_index("head")]).max() > 5 * MM
    # the toe tips (every third toe point) are the toes' end sites
    tips = [k for k, j in enumerate(rest.point_joints) if "Toe" in j][2::3]
    np.testing.assert_allclose(posed.point_offsets[tips], rest.point_offsets[tips], atol=1e-12)


def _rebased(motion, turns):
    """The same clip with other rest frames for some joints: offsets ``C_p^-1 o``, locals ``C_p^-1 L C_j``."""
    sk = motion.skeleton
    c = quat.identity((sk.n_joints,))
    for name, q in turns.items():
        c[sk.index(name)] = q
    p = sk.parents[1:]
    offsets = np.array(sk.offsets, copy=True)
    offsets[1:] = quat.rotate(quat.inv(c[p]), sk.offsets[1:])
    rot = np.array(motion.rotations, copy=True)
    rot[:, 0] = quat.mul(rot[:, 0], c[0])
    rot[:, 1:] = quat.mul(quat.mul(quat.inv(c[p]), rot[:, 1:]), c[1:])
    ends = quat.rotate(quat.inv(c[sk.end_site_parents]), sk.end_site_offsets)
    skeleton = dataclasses.replace(sk, offsets=offsets, end_site_offsets=ends)
    return motion.replace(skeleton=skeleton, rotations=rot)


def test_legs_that_do_not_hang_below_the_pelvis_are_not_a_standing_pose(cmu):
    """Leg frames turned upside down in the rest pose: the head above the pelvis, the legs up; the same motion."""
    walk = cmu("16_15")[FRAMES]
    flip = quat.from_axis_angle(np.array([1.0, 0.0, 0.0]), np.pi)
    legs = [f"{s}{j}" for s in ("Left", "Right") for j in ("UpLeg", "Leg", "Foot", "ToeBase")] + ["LHipJoint", "RHipJoint"]
    legs_up = _rebased(walk, dict.fromkeys(legs, flip))
    np.testing.assert_allclose(legs_up.global_positions(), walk.global_positions(), atol=1e-9)
    roles = walk.skeleton.roles  # the rest pose would confuse left and right (toes point back)
    with pytest.warns(RestPoseWarning, match=r"the left ankle is -0\.\d\d m below its hip"):
        body = Body.from_skeleton(legs_up, roles=roles)
    body0 = Body.from_skeleton(walk)
    com = np.abs(center_of_mass(legs_up, body) - center_of_mass(walk, body0)).max()
    assert com < TOL["x_bones"]["com"]
    # measured in that rest pose, the pelvis link would be 10 cm off
    rest = Body.from_skeleton(legs_up, pose="rest", roles=roles)
    err = np.abs(link_positions(legs_up, rest) - link_positions(walk, body0)).max(axis=(0, 2))
    assert err[rest.link_index("pelvis")] > 50 * MM


def test_a_skeleton_alone_with_a_degenerate_rest_pose_warns(converted):
    m, _ = converted("16_15", "x_bones")
    with pytest.warns(RestPoseWarning, match=r"Give the motion \(Body.from_skeleton\(motion\)\)"):
        Body.from_skeleton(m.skeleton)


def test_pose_is_validated(cmu):
    walk = cmu("16_15")[:30]
    with pytest.raises(ValueError, match=r"Expected `pose` to be 'rest' or finite local rotations of shape \(31, 4\)"):
        Body.from_skeleton(walk, pose=np.zeros((3, 4)))
    with pytest.raises(ValueError, match="zero quaternion"):
        Body.from_skeleton(walk, pose=np.zeros((31, 4)))
    with pytest.raises(ValueError, match="Expected `pose` to be 'rest'"):
        Body.from_skeleton(walk, pose="first")
    with pytest.raises(TypeError, match="Expected `motion` to be a Motion"):
        standing_pose(walk.skeleton)
    # a pose of the motion itself: a body measured in the first frame
    body = Body.from_skeleton(walk, pose=walk.rotations[0])
    assert body.n_links == 17 and np.isfinite(body.offsets).all()


@pytest.mark.parametrize("clip", CLIPS)
def test_a_static_reference_root_stays_static(converted, cmu, clip):
    """game_studio's ``joint_Root`` above the travelling ``Hips``: the touch-up turns the pelvis, never the root.

    The rotations of the part holding the root go onto the carrier joint (``Motion.carrier_joint``), so
    every channel of ``joint_Root`` keeps its input value and the other joints are where the touch-up of
    the CMU original puts them (it used to animate ``joint_Root`` by up to 7.8 cm).
    """
    m, name_map = converted(clip, "game_studio")
    ref = cmu(clip)[FRAMES]
    assert m.carrier_joint == m.skeleton.index("Hips") != 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        hist, hist0 = touch_up(m), touch_up(ref)
    out = hist.motion
    assert hist.best > 0
    np.testing.assert_array_equal(out.root_positions, m.root_positions)
    np.testing.assert_array_equal(out.rotations[:, 0], m.rotations[:, 0])
    np.testing.assert_array_equal(out.translations[:, 0], m.translations[:, 0])
    assert out.carrier_joint == m.carrier_joint
    cols = _columns(m, name_map, ref.skeleton.names)
    assert np.abs(out.global_positions()[:, cols] - hist0.motion.global_positions()).max() < 1 * MM
    np.testing.assert_allclose(hist.errors, hist0.errors, atol=1e-6)


def _bent_and_refined(motion):
    """Lesson 14's edit: both path ends pinned, the middle dragged 1 m sideways, then the feet planted (refine)."""
    p = motion.pelvis_positions[:, [0, 2]]
    n = len(p)
    pins = [PinPosition(0, 0, p[0], hard=True), PinPosition(0, n - 1, p[-1], hard=True),
            PinPosition(0, n // 2, p[n // 2] + [1.0, 0.0], hard=True)]
    return refine(edit([motion], pins).motions[0], contacts=foot_contacts(motion), reference=motion)


def test_an_edited_walk_is_touched_up_alike_under_a_static_root(converted, cmu):
    """A bent, refined walk below game_studio's static ``joint_Root`` gets the CMU layout's touch-up, pass after pass.

    The footplant step lowers the body where a leg cannot reach its plant; below a static root the motion
    lowers the pelvis while the forward kinematics handed back with it (``solve_goals(return_fk=True)``) had
    lowered ``joint_Root`` too.  The next adjustment set the pelvis's channels from that stale root position,
    so the studio file's touch-up sank below the CMU clip's from the second pass on (2.7 mm in lesson 14, 8.3 mm
    here).
    """
    m, name_map = converted("16_15", "game_studio")
    ref = cmu("16_15")[FRAMES]
    cols = _columns(m, name_map, ref.skeleton.names)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        bent0, bent = _bent_and_refined(ref), _bent_and_refined(m)
        # refine (Kim et al. s4.3, the same goal layer) is layout-free already
        assert np.abs(bent.global_positions()[:, cols] - bent0.global_positions()).max() < 1e-6
        hist0, hist = touch_up(bent0, iterations=3), touch_up(bent, iterations=3)
    assert hist.labels == hist0.labels and hist.best == hist0.best
    assert hist.best > len(hist.states[0].schedule)  # a pass after the first, where the stale root was read
    np.testing.assert_allclose(hist.errors, hist0.errors, atol=1e-9)
    for s, s0 in zip(hist.states, hist0.states, strict=True):
        gpos = s.motion.global_positions()
        # the kinematics each step carries along are the motion's, static root included
        assert np.abs(s.kinematics[1] - gpos).max() < 1e-9, s.label
        assert np.abs(gpos[:, cols] - s0.motion.global_positions()).max() < 1e-6, s.label
    np.testing.assert_array_equal(hist.motion.root_positions, m.root_positions)  # joint_Root stays static
    # and the touch-up moved the walk by centimetres (so agreeing is not trivial)
    assert np.abs(hist0.motion.global_positions() - bent0.global_positions()).max() > 10 * MM
