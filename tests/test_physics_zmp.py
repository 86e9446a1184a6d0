"""ZMP (equation 4), support polygons and distances; mass fitting (section 3.2)."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.path import Path as MplPath

from mocaplab.contacts import Contacts, foot_contacts
from mocaplab.physics import (
    GRAVITY,
    Body,
    balance,
    fit_masses,
    polygon_distance,
    signed_distance,
    support_polygon,
    zmp_from_links,
)


# ------------------------------------------------------------------ equation 4
def test_static_zmp_is_the_ground_projection_of_the_com():
    r = np.array([[[0.1, 1.0, 0.2], [0.3, 0.5, -0.2], [-0.2, 1.5, 0.0]]])
    m = np.array([1.0, 2.0, 3.0])
    z = zmp_from_links(r, np.zeros_like(r), m)
    com = (m @ r[0]) / m.sum()
    assert np.allclose(z[0], [com[0], 0.0, com[2]])


def test_horizontal_acceleration_moves_the_zmp_back_by_h_a_over_g():
    # one mass at height h accelerating forward: Z = x - h a / g
    r = np.array([[[0.0, 0.9, 0.0]]])
    a = np.array([[[0.0, 0.0, 2.0]]])
    z = zmp_from_links(r, a, np.array([70.0]))
    assert z[0, 2] == pytest.approx(-0.9 * 2.0 / 9.81)
    assert z[0, 0] == pytest.approx(0.0)


def test_free_fall_has_no_zmp_and_no_division_by_zero():
    r = np.zeros((2, 1, 3)) + [0.0, 1.0, 0.0]
    a = np.broadcast_to(GRAVITY, (2, 1, 3)).copy()
    with np.errstate(all="raise"):
        z = zmp_from_links(r, a, np.array([1.0]))
    assert np.all(np.isnan(z))


def test_zmp_shapes_are_checked():
    with pytest.raises(ValueError, match=r"\(F, L, 3\)"):
        zmp_from_links(np.zeros((2, 3)), np.zeros((2, 3)), np.ones(1))


# ------------------------------------------------------------- support polygon
def test_support_polygon_degenerate_cases():
    assert support_polygon(np.zeros((0, 2))).shape == (0, 2)
    assert support_polygon([[1.0, 2.0], [1.0, 2.0]]).tolist() == [[1.0, 2.0]]
    seg = support_polygon([[0.0, 0.0], [1.0, 1.0], [0.5, 0.5], [2.0, 2.0]])
    assert sorted(map(tuple, seg)) == [(0.0, 0.0), (2.0, 2.0)]
    sq = support_polygon([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5]])
    assert len(sq) == 4


def test_signed_distance_to_a_square():
    sq = [[0, 0], [1, 0], [1, 1], [0, 1]]
    assert signed_distance([0.5, 0.5], sq) == pytest.approx(-0.5)
    assert signed_distance([0.9, 0.5], sq) == pytest.approx(-0.1)
    assert signed_distance([2.0, 0.5], sq) == pytest.approx(1.0)
    assert signed_distance([2.0, 2.0], sq) == pytest.approx(np.sqrt(2.0))
    # a segment and a point have no inside
    assert signed_distance([0.5, 0.0], [[0, 0], [1, 0]]) == pytest.approx(0.0)
    assert signed_distance([0.5, 0.3], [[0, 0], [1, 0]]) == pytest.approx(0.3)
    assert signed_distance([3.0, 4.0], [[0, 0]]) == pytest.approx(5.0)


def _reference_distance(z, pts):
    """Brute force with scipy's ConvexHull and matplotlib's point-in-polygon test."""
    poly = support_polygon(pts)
    if len(poly) == 1:
        return float(np.linalg.norm(z - poly[0]))

    def seg(a, b):
        e = b - a
        t = np.clip((z - a) @ e / max(e @ e, 1e-300), 0, 1)
        return np.linalg.norm(z - a - t * e)

    d = min(seg(poly[k], poly[(k + 1) % len(poly)]) for k in range(len(poly)))
    inside = len(poly) >= 3 and MplPath(poly).contains_point(z)
    return -d if inside else d


def test_vectorised_distance_agrees_with_convex_hull(rng):
    n, p = 600, 8
    pts = rng.normal(size=(n, p, 2))
    act = rng.random((n, p)) < 0.6
    act[:50, 2:] = False  # one or two points
    pts[50:100, :, 1] = 2.0 * pts[50:100, :, 0]  # collinear sets
    z = rng.normal(size=(n, 2)) * 1.2
    z[50:75] = 0.5 * (pts[50:75, 0] + pts[50:75, 1])  # on a collinear set
    signed, proj = polygon_distance(z, pts, act)
    plain, _ = polygon_distance(z, pts, act, depth=False)
    for f in range(n):
        if not act[f].any():
            assert np.isnan(signed[f])
            continue
        ref = _reference_distance(z[f], pts[f, act[f]])
        assert signed[f] == pytest.approx(ref, abs=1e-9)
        assert plain[f] == pytest.approx(max(ref, 0.0), abs=1e-9)
        # the projection is a point of the hull at that distance
        assert np.linalg.norm(proj[f] - z[f]) == pytest.approx(max(ref, 0.0), abs=1e-9)


def test_nan_queries_stay_nan():
    s, p = polygon_distance(np.array([[np.nan, 0.0]]), np.zeros((1, 3, 2)) + [[0, 0], [1, 0], [0, 1]])
    assert np.isnan(s[0]) and np.all(np.isnan(p[0]))


# ------------------------------------------------------------------- clips
def test_captured_walk_keeps_its_zmp_near_the_support_polygon(cmu):
    walk = cmu("16_15").resample(30)
    bal = balance(walk)
    assert bal.ground.all()
    assert np.all(np.isfinite(bal.zmp))
    # a captured walk is balanced up to noise and model error: about a centimetre
    assert bal.mean_distance < 0.03
    inside = bal.signed_distance <= 0
    assert 0.3 < inside.mean() < 1.0
    assert np.allclose(bal.distance, np.maximum(bal.signed_distance, 0.0))
    poly = bal.polygon(10)
    assert poly.shape[1] == 3 and np.all(poly[:, 1] == 0)
    # touch-up histories share Balance objects: their arrays cannot be changed
    with pytest.raises(ValueError, match="read-only"):
        bal.distance[0] = 1.0


def test_flight_frames_have_no_zmp(cmu):
    jump = cmu("16_05").resample(30)
    c = foot_contacts(jump)
    bal = balance(jump, contacts=c)
    flight = ~c.planted_any()
    assert flight.sum() >= 5
    assert np.all(np.isnan(bal.zmp[flight])) and np.all(np.isnan(bal.distance[flight]))
    assert np.all(np.isfinite(bal.zmp[~flight, 0]))
    assert bal.mean_distance == pytest.approx(np.nanmean(bal.distance))


def test_contacts_must_match_the_motion(cmu):
    walk = cmu("16_15")[:40]
    bad = Contacts(("LeftFoot",), np.ones((10, 1), dtype=bool), walk.fps)
    with pytest.raises(ValueError, match="40 frames"):
        balance(walk, contacts=bad)


# ---------------------------------------------------------------- masses
def test_fitted_masses_put_the_zmp_closer_to_the_polygon(cmu):
    refs = [cmu("16_15").resample(30), cmu("16_11").resample(30)]
    fit = fit_masses(refs, max_iterations=40)
    assert fit.after < fit.before
    assert fit.body.total_mass == pytest.approx(fit.initial.total_mass)
    assert np.all(fit.body.masses > 0)
    m = fit.body.mass_table()
    assert m["left_thigh"] == pytest.approx(m["right_thigh"])
    # the fitted distribution, not just the objective, is what balance() sees
    after = np.mean([balance(r, fit.body).mean_distance for r in refs])
    before = np.mean([balance(r, fit.initial).mean_distance for r in refs])
    assert after < before


def test_fit_masses_ignores_the_overall_scale(cmu):
    walk = cmu("02_01").resample(30)
    light = Body.from_skeleton(walk, total_mass=50.0)
    heavy = Body.from_skeleton(walk, total_mass=100.0)
    a = fit_masses(walk, light, max_iterations=20)
    b = fit_masses(walk, heavy, max_iterations=20)
    assert np.allclose(a.body.masses * 2.0, b.body.masses, rtol=1e-6)
    assert a.after == pytest.approx(b.after, rel=1e-6)


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_fit_masses_on_any_skeleton_layout(cmu):
    from test_physics_body import game_studio, static_root

    walk = cmu("16_15").resample(30)
    ref = fit_masses(walk, max_iterations=20)
    for other in (game_studio(walk), static_root(walk)):
        fit = fit_masses(other, max_iterations=20)  # default body and contacts from the roles
        assert fit.body.link_names == ref.body.link_names
        assert np.allclose(fit.body.masses, ref.body.masses, rtol=1e-6)
        assert fit.after == pytest.approx(ref.after, rel=1e-6)
    # role overrides reach the default body: the neck one joint higher adds a middle-trunk link
    moved = fit_masses(walk, max_iterations=5, roles={"neck": "Neck1"})
    assert moved.body.n_links == ref.body.n_links + 1 and "middle_trunk_3" in moved.body.link_names


def test_fit_masses_validates_its_inputs(cmu):
    walk = cmu("16_15")[:60]
    with pytest.raises(ValueError, match="at least one"):
        fit_masses([])
    with pytest.raises(ValueError, match="one Contacts per motion"):
        fit_masses([walk, walk], contacts=[foot_contacts(walk)])
    with pytest.raises(ValueError, match="regularization"):
        fit_masses(walk, regularization=-1.0)
