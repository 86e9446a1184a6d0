"""Hierarchical displacement maps (Lee and Shin 1999)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import BSpline

from mocaplab import quat
from mocaplab.displacement import (
    DisplacementMap,
    displacement_between,
    fit_bspline,
    fit_hierarchical,
    uniform_knots,
)
from mocaplab.motion import Motion, Skeleton


def _spline_signal(rng, n_frames: int, spacing: float, dims: int) -> np.ndarray:
    t = uniform_knots(n_frames, spacing)
    c = rng.normal(size=(len(t) - 4, dims))
    return BSpline(t, c, 3)(np.arange(n_frames, dtype=float))


def _motion(n_frames: int = 120, n_joints: int = 3) -> Motion:
    sk = Skeleton([f"j{k}" for k in range(n_joints)], [-1] + list(range(n_joints - 1)), np.tile([0, 0.3, 0], (n_joints, 1)))
    t = np.linspace(0, 1, n_frames)[:, None]
    rot = quat.exp(np.stack([np.sin(3 * t) * [0.3, 0.1, 0.0]] * n_joints, axis=1))
    return Motion(sk, rot, np.hstack([t, np.zeros_like(t), t]), 60.0)


def test_uniform_knots_cover_the_clip():
    t = uniform_knots(101, 10.0)
    assert t[3] == 0.0 and t[-4] >= 100.0
    np.testing.assert_allclose(np.diff(t), 10.0)
    assert len(uniform_knots(1, 5.0)) == 8
    with pytest.raises(ValueError, match="`spacing` > 0"):
        uniform_knots(10, 0.0)


def test_fit_reproduces_a_spline_of_the_same_knots(rng):
    y = _spline_signal(rng, 300, 20.0, 4)
    fit = fit_bspline(y, spacing=20.0)
    np.testing.assert_allclose(fit(np.arange(300.0)), y, atol=1e-6)


def test_hierarchy_is_exact_at_the_coarse_level_for_smooth_signals(rng):
    y = _spline_signal(rng, 400, 32.0, 3)
    levels = fit_hierarchical(y, spacing=32.0, levels=4)
    x = np.arange(400.0)
    np.testing.assert_allclose(levels[0](x), y, atol=1e-6)
    for finer in levels[1:]:
        assert np.abs(finer(x)).max() < 1e-6
    assert [float(s.t[1] - s.t[0]) for s in levels] == [32.0, 16.0, 8.0, 4.0]


def test_finer_levels_reduce_the_residual_and_tolerance_stops_early(rng):
    x = np.arange(500.0)
    y = np.sin(x / 7.0) + 0.3 * np.sin(x / 2.3)
    errs = []
    for n in range(1, 5):
        total = sum(s(x) for s in fit_hierarchical(y, spacing=32.0, levels=n))
        errs.append(np.abs(total - y).max())
    assert all(b < a for a, b in zip(errs, errs[1:], strict=False))
    short = fit_hierarchical(y, spacing=32.0, levels=6, tolerance=errs[1] * 1.01)
    assert len(short) == 2


def test_map_is_smooth_on_noisy_corrections(rng):
    n = 600
    clean = np.sin(np.linspace(0, 4 * np.pi, n))[:, None] * [0.05, 0.02, 0.0]
    noisy = clean + rng.normal(scale=0.01, size=(n, 3))
    dm = DisplacementMap.fit(root=noisy, spacing=60, levels=2)
    root, _ = dm.evaluate()
    # much smoother than the raw corrections, and close to the clean signal
    assert np.abs(np.diff(root, 2, axis=0)).max() < 0.05 * np.abs(np.diff(noisy, 2, axis=0)).max()
    assert np.sqrt(np.mean((root - clean) ** 2)) < 0.004  # well below the noise (0.01)


def test_weights_pull_the_fit_to_constrained_frames():
    n = 200
    y = np.zeros((n, 1))
    y[100] = 1.0  # a spike only the finest knots could follow
    w = np.ones(n)
    w[100] = 1e4
    plain = fit_bspline(y, spacing=10.0)(np.arange(n, dtype=float))
    heavy = fit_bspline(y, spacing=10.0, weights=w)(np.arange(n, dtype=float))
    assert abs(heavy[100, 0] - 1.0) < 0.05 < abs(plain[100, 0] - 1.0)


def test_zero_weights_give_zero_not_nan():
    n = 100
    w = np.zeros(n)
    w[40:60] = 1.0
    y = np.ones((n, 2))
    fit = fit_bspline(y, spacing=5.0, weights=w)(np.arange(n, dtype=float))
    assert np.all(np.isfinite(fit))
    np.testing.assert_allclose(fit[45:55], 1.0, atol=1e-6)
    assert np.abs(fit[:20]).max() < 1e-6


def test_apply_uses_post_multiplication():
    m = _motion(10)
    d = np.zeros((10, 3, 3))
    d[:, 1] = [0.0, 0.2, 0.0]
    dm = DisplacementMap.fit(rotations=d, spacing=4, levels=1)
    out = dm.apply(m)
    want = quat.mul(m.rotations[:, 1], quat.exp(d[:, 1]))
    np.testing.assert_allclose(out.rotations[:, 1], want, atol=1e-9)
    np.testing.assert_array_equal(out.rotations[:, 0], m.rotations[:, 0])
    assert dm.joints == (1,)


def test_between_then_apply_round_trip():
    m = _motion(240)
    t = np.linspace(0, 1, 240)[:, None]
    d_rot = np.zeros((240, 3, 3))
    d_rot[:, 2] = np.sin(2 * np.pi * t) * [0.2, 0.0, 0.1]
    d_root = np.cos(2 * np.pi * t) * [0.0, 0.05, 0.0]
    after = m.replace(
        rotations=np.concatenate([m.rotations[:, :2], quat.mul(m.rotations[:, 2:], quat.exp(d_rot[:, 2:]))], axis=1),
        root_positions=m.root_positions + d_root,
    )
    r, q = displacement_between(m, after)
    np.testing.assert_allclose(r, d_root, atol=1e-12)
    np.testing.assert_allclose(q[:, 2], d_rot[:, 2], atol=1e-9)
    dm = DisplacementMap.between(m, after, spacing=30, levels=3)
    back = dm.apply(m)
    np.testing.assert_allclose(back.root_positions, after.root_positions, atol=1e-4)
    assert np.degrees(quat.angle(quat.mul(quat.inv(back.rotations), after.rotations))).max() < 0.05
    # the input is untouched
    assert m.rotations.flags.writeable is False
    assert dm.evaluate(upto=0)[0].max() == 0.0


def test_bad_inputs():
    with pytest.raises(ValueError, match="`root` and/or `rotations`"):
        DisplacementMap.fit()
    with pytest.raises(ValueError, match=r"`rotations` of shape \(F, J, 3\)"):
        DisplacementMap.fit(rotations=np.zeros((5, 3)))
    with pytest.raises(ValueError, match="`weights`"):
        fit_bspline(np.zeros(5), spacing=2.0, weights=-np.ones(5))
    with pytest.raises(ValueError, match="`levels`"):
        fit_hierarchical(np.zeros(5), spacing=2.0, levels=0)
    dm = DisplacementMap.fit(rotations=np.ones((5, 3, 3)), spacing=2.0)
    with pytest.raises(ValueError, match="Expected a motion of 5 frames"):
        dm.apply(_motion(6))
