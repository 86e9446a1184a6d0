"""Flight measures of a touch-up (Shin et al. 2003, section 3.4): fitted gravity and angular-momentum spread."""

from __future__ import annotations

import numpy as np
import pytest

from mocaplab import quat
from mocaplab.contacts import Contacts, foot_contacts
from mocaplab.physics import Body, TouchUpSession, angular_momentum, center_of_mass
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
