"""Body model: link masses, centre of mass, momenta, smoothed derivatives."""

from __future__ import annotations

import numpy as np
import pytest

from mocaplab import quat
from mocaplab.motion import Motion, Skeleton
from mocaplab.physics import (
    DE_LEVA_MALE,
    Body,
    LinkSpec,
    angular_momentum,
    center_of_mass,
    linear_momentum,
    link_positions,
    smoothed_derivatives,
)


def test_de_leva_table_sums_to_the_whole_body():
    limbs = ("upper_arm", "forearm", "hand", "thigh", "shank", "foot")
    total = sum(v * (2 if k in limbs else 1) for k, v in DE_LEVA_MALE.items())
    assert total == pytest.approx(100.0, abs=0.01)


def test_cmu_body_masses_follow_the_table(cmu):
    walk = cmu("16_15")
    body = Body.from_skeleton(walk, total_mass=80.0)
    assert body.n_links == 17
    assert body.total_mass == pytest.approx(80.0, abs=1e-9)
    m = body.mass_table()
    assert m["left_thigh"] == pytest.approx(0.8 * 14.16)
    assert m["lower_back"] + m["upper_back"] == pytest.approx(0.8 * 16.33)
    assert m["left_foot"] == m["right_foot"]
    mirror = body.mirror_map()
    assert body.link_names[mirror[body.link_index("left_hand")]] == "right_hand"


def test_daz_skeleton_maps_by_name(cmu):
    salsa = cmu("60_10")
    body = Body.from_skeleton(salsa)
    assert body.total_mass == pytest.approx(70.0)
    com = center_of_mass(salsa[:20], body)
    hips = salsa.global_positions()[:20, 0]
    # the centre of mass of a standing dancer is near the hips (within 20 cm)
    assert np.all(np.linalg.norm(com - hips, axis=1) < 0.2)


def test_unknown_skeleton_raises_with_a_hint():
    sk = Skeleton(["root", "a"], [-1, 0], [[0, 0, 0], [0, 1, 0]])
    with pytest.raises(ValueError, match="from_links"):
        Body.from_skeleton(sk)


def test_from_links_and_validation():
    sk = Skeleton(["root", "a"], [-1, 0], [[0, 0, 0], [0, 1.0, 0]])
    body = Body.from_links(sk, [LinkSpec("rod", "thigh", 1.0, "root", ("root",), ("a",))], total_mass=100.0)
    assert body.offsets[0].tolist() == [0.0, 0.5, 0.0]
    assert body.masses[0] == pytest.approx(14.16)
    with pytest.raises(ValueError, match="masses"):
        body.with_masses([-1.0])
    with pytest.raises(KeyError, match="mass table"):
        Body.from_links(sk, [LinkSpec("rod", "tail", 1.0, "root", ("root",), ("a",))])


def _rod_motion(n: int = 60, fps: float = 30.0, spin: float = 0.0, velocity=(0.0, 0.0, 0.0)) -> tuple[Motion, Body]:
    """Two masses on a horizontal rod, spinning about +Y and translating."""
    sk = Skeleton(["root", "tip"], [-1, 0], [[0, 0, 0], [1.0, 0, 0]])
    t = np.arange(n) / fps
    rot = np.zeros((n, 2, 4))
    rot[:, 0] = quat.from_yaw(spin * t)
    rot[:, 1, 3] = 1.0
    root = np.outer(t, velocity) + [0.0, 1.0, 0.0]
    m = Motion(sk, rot, root, fps)
    body = Body.from_links(
        sk,
        [
            LinkSpec("near", "thigh", 1.0, "root", ("root",), ("root",)),
            LinkSpec("far", "thigh", 1.0, "tip", ("tip",), ("tip",)),
        ],
        total_mass=100.0 / 14.16,
    )
    return m, body


def test_com_and_linear_momentum_of_a_translating_body():
    m, body = _rod_motion(velocity=(0.5, 0.0, -1.0))
    com = center_of_mass(m, body)
    assert np.allclose(com[0], [0.5, 1.0, 0.0])
    p = linear_momentum(m, body)
    assert np.allclose(p, body.total_mass * np.array([0.5, 0.0, -1.0]), atol=1e-9)
    # a pure translation has no angular momentum about the centre of mass
    assert np.allclose(angular_momentum(m, body), 0.0, atol=1e-9)


def test_angular_momentum_of_a_spinning_rod_is_i_omega():
    m, body = _rod_motion(n=240, fps=120.0, spin=2.0)
    h = angular_momentum(m, body, width=0.0)
    # two unit masses 1 m apart spin about the first: about the COM, I = 2 * 0.5^2
    assert np.allclose(h[:, 1], 0.5 * 2.0, rtol=1e-3)
    assert np.allclose(h[:, [0, 2]], 0.0, atol=1e-9)
    # about the rod's first mass: I = 1
    h0 = angular_momentum(m, body, about=m.root_positions, width=0.0)
    assert np.allclose(h0[:, 1], 2.0, rtol=1e-3)
    # the default smoothing (5 frames at 30 fps) shrinks a 2 rad/s spin by < 1 %
    assert np.allclose(angular_momentum(m, body)[:, 1], 1.0, rtol=1e-2)


def test_smoothed_derivatives_are_exact_for_parabolas():
    t = np.arange(50) / 30.0
    x = np.stack([3 * t**2 - t + 1, -4.905 * t**2 + 2 * t], axis=1)
    for width in (0.0, 5.0, 40.0):
        _, v, a = smoothed_derivatives(x, 30.0, width=width)
        assert np.allclose(a, [6.0, -9.81], atol=1e-8)
        assert np.allclose(v, np.stack([6 * t - 1, -9.81 * t + 2], axis=1), atol=1e-8)


def test_smoothed_derivatives_short_clips_do_not_fail():
    for n in (1, 2, 3):
        s, v, a = smoothed_derivatives(np.arange(n, dtype=float)[:, None], 30.0, width=5.0)
        assert s.shape == v.shape == a.shape == (n, 1)
        assert np.all(np.isfinite(a))


def test_link_positions_checks_the_skeleton(cmu):
    walk, salsa = cmu("16_15"), cmu("60_10")
    body = Body.from_skeleton(walk)
    assert link_positions(walk[:3], body).shape == (3, 17, 3)
    with pytest.raises(ValueError, match="skeleton"):
        link_positions(salsa[:3], body)


def test_support_points_give_heel_and_toe_points(cmu):
    walk = cmu("16_15")[:5]
    body = Body.from_skeleton(walk, foot_width=0.0)
    pts, col = body.support_points(walk, ("LeftFoot", "LeftToeBase", "Head"))
    assert col.tolist() == [0, 1, 1, 2]
    g = walk.global_positions()
    ankle, ball = g[:, walk.skeleton.index("LeftFoot")], g[:, walk.skeleton.index("LeftToeBase")]
    heel = pts[:, 0]
    # the heel lies behind the ankle, the toe points ahead of the ball, along the foot
    fwd = (ball - ankle)[:, [0, 2]]
    assert np.all(np.einsum("fc,fc->f", (heel - ankle)[:, [0, 2]], fwd) < 0)
    assert np.allclose(pts[:, 1], ball)
    assert np.all(np.einsum("fc,fc->f", (pts[:, 2] - ball)[:, [0, 2]], fwd) > 0)
    assert np.allclose(pts[:, 3], g[:, walk.skeleton.index("Head")])
