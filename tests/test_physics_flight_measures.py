"""Flight measures of a touch-up (Shin et al. 2003, section 3.4): fitted gravity and angular-momentum spread."""

from __future__ import annotations

import numpy as np
import pytest

from mocaplab import quat
from mocaplab.contacts import Contacts, foot_contacts
from mocaplab.physics import Body, TouchUpSession, angular_momentum, center_of_mass, link_positions, touch_up
from mocaplab.physics.body import DE_LEVA_GYRATION_MALE, LinkSpec
from mocaplab.physics.flight import FlightMeasure, flight_measures


def _thrown(walk, g: float, spin: float = 0.0):
    """The first pose of ``walk`` held still and thrown: its root flies a parabola with gravity ``g``.

    Frames 10-39 are the flight (no contact); ``spin`` turns the body about
    the vertical axis at a rate growing during the flight (radians per
    second per second), so its angular momentum is not constant.
    """
    n, fps = 50, 30.0
    t = np.arange(n) / fps
    tf = np.clip(t - t[10], 0.0, t[39] - t[10])
    root = np.repeat(walk.root_positions[:1], n, axis=0) + np.stack(
        [0.8 * tf, 1.2 * tf - 0.5 * g * tf**2, np.zeros(n)], axis=1
    )
    q = np.repeat(walk.rotations[:1], n, axis=0)
    q[:, 0] = quat.mul(quat.from_yaw(0.5 * spin * tf**2), q[:, 0])
    m = walk[:n].replace(rotations=q, root_positions=root)
    mask = np.ones((n, 1), dtype=bool)
    mask[10:40] = False
    return m, Contacts(("LeftFoot",), mask, fps)


def test_a_thrown_rigid_body_has_its_gravity_and_no_spread(cmu) -> None:
    walk = cmu("16_15").resample(30)  # _thrown counts frames at 30 fps
    body = Body.from_skeleton(walk)
    m, contacts = _thrown(walk, 9.81)
    (f,) = flight_measures(m, body, contacts)
    assert isinstance(f, FlightMeasure) and (f.start, f.stop) == (10, 40)
    assert f.gravity == pytest.approx(9.81, rel=1e-6)
    # translating a rigid body: no angular momentum about its centre of mass (the smoothing leaks a little at the ends)
    assert f.momentum_spread < 1e-3
    slow, _ = _thrown(walk, 6.0)
    assert flight_measures(slow, body, contacts)[0].gravity == pytest.approx(6.0, rel=1e-6)
    spun, _ = _thrown(walk, 9.81, spin=6.0)
    g = flight_measures(spun, body, contacts)[0]
    assert g.gravity == pytest.approx(9.81, rel=1e-6) and g.momentum_spread > 0.5
    # the spread is the mean distance of h_CM from its flight mean (what lesson 10 measures)
    h = angular_momentum(spun, body)[10:40]
    assert g.momentum_spread == pytest.approx(np.linalg.norm(h - h.mean(axis=0), axis=1).mean(), rel=1e-12)
    # the centre of mass can be passed in (computed once by the balance analysis)
    assert flight_measures(spun, body, contacts, com=center_of_mass(spun, body)) == (g,)
    with pytest.raises(ValueError, match="com"):
        flight_measures(spun, body, contacts, com=np.zeros((3, 3)))
    assert flight_measures(m, body, Contacts(("LeftFoot",), np.ones((50, 1), dtype=bool), 30.0)) == ()


def test_touch_up_states_carry_their_flight_measures(cmu) -> None:
    jump = cmu("16_05").resample(30)
    c = foot_contacts(jump)
    s = TouchUpSession(jump, contacts=c, footplants="ik")
    (f,) = s.current.flights
    assert abs(f.gravity - 9.81) < 0.05 * 9.81  # the capture is ballistic to a few percent (lesson 10)
    (again,) = flight_measures(jump, s.current.body, c)
    assert (again.start, again.stop) == (f.start, f.stop)
    assert again.gravity == pytest.approx(f.gravity, rel=1e-12) and again.momentum_spread == f.momentum_spread
    s.forward()
    assert s.current.flights != s.input.flights  # a flight step changes the flight


def test_a_flight_too_short_for_a_parabola_says_so(cmu) -> None:
    walk = cmu("16_15").resample(30)
    body = Body.from_skeleton(walk)
    m, contacts = _thrown(walk, 9.81)
    mask = np.ones((m.n_frames, 1), dtype=bool)
    mask[10:12] = False  # two frames in the air
    (two,) = flight_measures(m, body, Contacts(("LeftFoot",), mask, 30.0))
    assert (two.frames, two.fitted) == (2, False) and np.isnan(two.gravity)
    assert two.gravity_text() == "too short to fit (2 frames)"
    mask[12] = False  # three frames fix a parabola exactly
    (three,) = flight_measures(m, body, Contacts(("LeftFoot",), mask, 30.0))
    assert three.fitted and three.gravity == pytest.approx(9.81, rel=1e-6)
    assert three.gravity_text() == "9.81 m/s²"


# ------------------------------------------------------------ rigid segments (issue 24 item 7)
def test_each_link_has_de_levas_radii_of_gyration(cmu) -> None:
    walk = cmu("16_15")
    body = Body.from_skeleton(walk.skeleton)
    sk = walk.skeleton
    k = body.link_index("left_thigh")
    hip, knee = sk.index("LeftUpLeg"), sk.index("LeftLeg")
    thigh = np.linalg.norm(walk.skeleton.offsets[knee])  # the rest pose is the reference pose of CMU skeletons
    values, vectors = np.linalg.eigh(body.inertia[k])
    radii = np.sqrt(values / body.masses[k])
    np.testing.assert_allclose(np.sort(radii), np.sort(np.array(DE_LEVA_GYRATION_MALE["thigh"]) / 100 * thigh), rtol=1e-9)
    # the smallest (longitudinal) radius is about the thigh's own axis
    along = vectors[:, 0]
    assert abs(along @ sk.offsets[knee] / thigh) > 1 - 1e-9 and body.owners[k] == hip
    # the inertia scales with the mass, and a hand-made body has none unless given
    heavier = body.with_masses(2 * body.masses)
    np.testing.assert_allclose(heavier.inertia, 2 * body.inertia)
    by_hand = Body.from_links(walk, [LinkSpec("thigh", "thigh", 1.0, "LeftUpLeg", ("LeftUpLeg",), ("LeftLeg",))])
    assert by_hand.inertia is None
    with pytest.raises(ValueError, match=r"Body.inertia"):
        angular_momentum(walk[:30], by_hand, inertia="segments")
    with pytest.raises(ValueError, match=r'`inertia` to be "points" .* got \'box\''):
        angular_momentum(walk[:30], body, inertia="box")
    with pytest.raises(ValueError, match=r"shape \(17, 3, 3\)"):
        Body(body.joint_names, body.link_names, body.owners, body.offsets, body.masses, inertia=np.eye(3))


def test_a_spinning_body_has_the_angular_momentum_of_its_rigid_segments(cmu) -> None:
    """A pose turning about the vertical at 1.5 rad/s: h = (I of the points about the centre + the segments' own) w."""
    walk = cmu("16_15").resample(30)
    body = Body.from_skeleton(walk)
    n, rate = 40, 1.5
    yaw = quat.from_yaw(rate * np.arange(n) / walk.fps)
    q = np.repeat(walk.rotations[:1], n, axis=0)
    q[:, 0] = quat.mul(yaw, q[:, 0])
    spin = walk[:n].replace(rotations=q, root_positions=np.repeat(walk.root_positions[:1], n, axis=0))
    inner = slice(10, 30)
    h_points = angular_momentum(spin, body)[inner]
    h_rigid = angular_momentum(spin, body, inertia="segments")[inner]
    # by hand, on each frame: the point masses' inertia about their centre, and each segment's own turned to the world
    r = link_positions(spin, body)[inner]
    r = r - np.einsum("l,flc->fc", body.masses, r)[:, None] / body.total_mass
    points = np.einsum("l,flc,flc->f", body.masses, r, r)[:, None, None] * np.eye(3) - np.einsum(
        "l,flc,fld->fcd", body.masses, r, r
    )
    turn = quat.to_matrix(spin.global_rotations()[inner][:, body.owners])
    own = np.einsum("flij,ljk,flmk->fim", turn, body.inertia, turn)
    w = np.array([0.0, rate, 0.0])
    np.testing.assert_allclose(h_points, points @ w, rtol=0.01, atol=1e-3)
    np.testing.assert_allclose(h_rigid, (points + own) @ w, rtol=0.01, atol=1e-3)
    share = np.linalg.norm(h_rigid - h_points, axis=1).mean() / np.linalg.norm(h_rigid, axis=1).mean()
    assert share > 0.05, share  # the segments' own spin is not negligible: the checks above can tell it


def test_flights_say_how_much_of_their_angular_momentum_is_spin(cmu) -> None:
    jump = cmu("16_01").resample(30)
    body = Body.from_skeleton(jump)
    c = foot_contacts(jump)
    (points,) = flight_measures(jump, body, c)
    (rigid,) = flight_measures(jump, body, c, inertia="segments")
    assert points.spin_share is None and (rigid.start, rigid.stop) == (points.start, points.stop)
    h, hp = angular_momentum(jump, body, inertia="segments"), angular_momentum(jump, body)
    a, b = rigid.start, rigid.stop
    share = np.linalg.norm(h[a:b] - hp[a:b], axis=1).mean() / np.linalg.norm(h[a:b], axis=1).mean()
    assert rigid.spin_share == pytest.approx(share, rel=1e-12)
    assert 0.1 < rigid.spin_share < 0.4  # 22 %: the paper's box model differed from its point masses by under 2 %


def test_segments_keep_the_rigid_bodys_angular_momentum_where_points_do_not(cmu) -> None:
    """The jog 16_35 at 30 fps: the point-mass touch-up raises the rigid body's spread on its three flights."""
    jog = cmu("16_35").resample(30)
    c = foot_contacts(jog)
    body = Body.from_skeleton(jog)
    before = [f.momentum_spread for f in flight_measures(jog, body, c, inertia="segments")]
    spreads = {}
    for inertia in ("points", "segments"):
        out = touch_up(jog, body=body, contacts=c, inertia=inertia)
        assert out.states[-1].inertia == inertia and out.states[0].flights == flight_measures(
            jog, body, c, com=out.states[0].balance.com, inertia=inertia
        )
        spreads[inertia] = [f.momentum_spread for f in flight_measures(out.motion, body, c, inertia="segments")]
    assert len(before) == 3
    assert all(p > b for p, b in zip(spreads["points"], before, strict=True)), (before, spreads)
    assert all(s < 0.8 * b for s, b in zip(spreads["segments"], before, strict=True)), (before, spreads)
