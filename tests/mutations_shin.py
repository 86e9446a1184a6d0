"""Mutations of the Shin et al. 2003 lessons (08-10), run by ``test_lessons_falsifiable.py``.

Each case is ``(lesson, switch, message)``: ``switch(monkeypatch)`` breaks one
piece of the method, and the lesson must then fail an ``assert`` whose
message contains ``message`` (None: any assert).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

L08 = "08_center_of_mass_and_zmp.ipynb"
L09 = "09_touch_up_ground.ipynb"
L10 = "10_touch_up_flight.ipynb"


# ------------------------------------------------------------------ the switches
def no_horizontal_acceleration(monkeypatch: pytest.MonkeyPatch) -> None:
    """Equation 4 without its horizontal-acceleration terms (the ZMP as a weighted centre of mass)."""
    from mocaplab.physics import zmp

    real = zmp._zmp_xz

    def vertical_only(r, a, m, weight):
        a = np.array(a, dtype=float, copy=True)
        a[..., 0] = 0.0
        a[..., 2] = 0.0
        return real(r, a, m, weight)

    monkeypatch.setattr(zmp, "_zmp_xz", vertical_only)


def no_ground_adjustment(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every ground adjustment of the touch-up leaves the motion as it is."""
    from mocaplab.physics import state  # step() looks _ground_step up there (its home is physics.ground)

    monkeypatch.setattr(state, "_ground_step", lambda posed, *args, **kwargs: posed)


def no_flight_adjustment(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every flight adjustment of the touch-up leaves the motion as it is (the ground ones still run)."""
    from mocaplab.physics import state  # step() looks _flight_step up there (its home is physics.flight)

    monkeypatch.setattr(state, "_flight_step", lambda posed, *args, **kwargs: posed)


def _ground_adjustment_off_where(monkeypatch: pytest.MonkeyPatch, off: Callable[[object], bool]) -> None:
    """The ground adjustments leave the motion as it is when ``off(balance)`` holds (the others run as ever)."""
    from mocaplab.physics import state

    real = state._ground_step

    def step(posed, body, adj, sets, bal, *args, **kwargs):
        return posed if off(bal) else real(posed, body, adj, sets, bal, *args, **kwargs)

    monkeypatch.setattr(state, "_ground_step", step)


def no_ground_adjustment_on_a_slope(monkeypatch: pytest.MonkeyPatch) -> None:
    """The ground adjustments are off on a sloped floor: lesson 09's uphill walk (section 4.4) is left as tilted.

    The level walks of the lesson (the floor estimated at y = 0) are touched up as ever, so only the uphill
    section's claims can fail.
    """
    from mocaplab.physics import zmp

    _ground_adjustment_off_where(monkeypatch, lambda bal: not bal.__dict__.get("_ground", zmp._LEVEL).identity)


def no_ground_adjustment_with_flights(monkeypatch: pytest.MonkeyPatch) -> None:
    """The ground adjustments are off on clips with flight frames: lesson 09's walk-to-jog (section 4.2) stays upright.

    The walks of the lesson have no flight, so only the walk-to-jog section's claims can fail.
    """
    _ground_adjustment_off_where(monkeypatch, lambda bal: not bool(np.all(bal.ground)))


def closest_approach_with_zero_weight(monkeypatch: pytest.MonkeyPatch) -> None:
    """Ground frames without an exact solution get no correction (an earlier version), not the closest approach.

    Section 3.3 applies the rotation that brings the ZMP closest; here those frames keep their pose, so only
    the frames equation 7 solves exactly move.  :func:`mocaplab.physics.ground_reach` still tells them apart.
    """
    from mocaplab.physics import ground  # _ground_step looks _ground_rotation up there

    real = ground._ground_rotation

    def exact_only(*args, **kwargs):
        omega, centre, exact = real(*args, **kwargs)
        return np.where(exact[:, None], omega, 0.0), centre, exact

    monkeypatch.setattr(ground, "_ground_rotation", exact_only)


def no_segment_spin(monkeypatch: pytest.MonkeyPatch) -> None:
    """Rigid segments without their own spin: ``inertia="segments"`` counts the point masses only."""
    from mocaplab.physics import body, flight

    def none(motion, *args, **kwargs):
        return np.zeros((motion.n_frames, 3))

    monkeypatch.setattr(body, "_segment_spin", none)
    monkeypatch.setattr(flight, "_segment_spin", none)


def flight_steps_on_point_masses(monkeypatch: pytest.MonkeyPatch) -> None:
    """The flight adjustments keep the point masses' angular momentum whatever ``inertia=`` says."""
    from mocaplab.physics import state

    real = state._flight_step

    def points(*args, **kwargs):
        return real(*args[:7], "points")

    monkeypatch.setattr(state, "_flight_step", points)


CASES: list[tuple[str, Callable[[pytest.MonkeyPatch], None], str | None]] = [
    (L08, no_horizontal_acceleration, "carry the ZMP away from the COM"),
    (L09, no_ground_adjustment, "one adjustment already helps"),
    (L09, no_ground_adjustment_on_a_slope, "tilts the climber forward"),
    (L09, no_ground_adjustment_with_flights, "leans forward while it speeds up"),
    # caught first by the full touch-up's bound (x0.60 against x0.35), then by the section on the rule itself
    (L09, closest_approach_with_zero_weight, "the mean ZMP distance falls to a third or less"),
    (L10, no_flight_adjustment, "little swerve left in the air"),
    (L10, no_ground_adjustment, "the landing gets a balancing action"),
    (L10, no_segment_spin, "far above the paper's 2 %"),
    (L10, flight_steps_on_point_masses, "the segments make it more constant"),
]
