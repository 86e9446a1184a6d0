"""Fitting splines and displacement maps (Coleman 2008, section 4.1.1, Appendix A); extraction."""

from __future__ import annotations

import numpy as np
import pytest

from mocaplab import quat
from mocaplab.staggered import (
    extract,
    fit_rotation_tangents,
    fit_translation_tangents,
    quat_bezier,
    rotation_objective,
)
from mocaplab.staggered.fit import W_C, W_F


def reconstruction_error(a, b) -> tuple[float, float]:
    rot = float(quat.angle(quat.mul(quat.inv(a.rotations), b.rotations)).max())
    pos = float(np.abs(a.root_positions - b.root_positions).max())
    return rot, pos


@pytest.mark.parametrize("clip", ["16_15", "05_02", "16_05"])
def test_extract_then_evaluate_reproduces_every_frame(cmu, clip: str) -> None:
    m = cmu(clip)
    sm = extract(m)
    out = sm.evaluate()
    assert out.n_frames == m.n_frames and out.fps == m.fps
    rot, pos = reconstruction_error(out, m)
    assert rot < 1e-6 and pos < 1e-6
    # sparse: far fewer poses than frames, refinements bounded by 0.25 s
    assert sm.n_poses < m.n_frames / 10
    assert np.abs(sm.refinements).max() <= 0.25 + 1e-12
    assert sm.times[0] == 0.0 and sm.times[-1] == pytest.approx(m.duration)
    assert np.all(sm.refinements[[0, -1]] == 0.0)
    assert sm.refinements.shape == (sm.n_poses, m.n_joints + 1)


def test_culling_options(cmu) -> None:
    m = cmu("16_05")
    full = extract(m, optimize=False)
    few = extract(m, max_poses=6, optimize=False)
    assert few.n_poses == 6 and set(np.round(few.times, 9)) <= set(np.round(full.times, 9))
    half = extract(m, fraction=0.5, optimize=False)
    assert 2 < half.n_poses < full.n_poses
    window = extract(m, interval=(0.5, 1.5), optimize=False)
    inner = window.times[1:-1]
    assert np.all((inner >= 0.5) & (inner <= 1.5))
    rot, pos = reconstruction_error(few.evaluate(), m)
    assert rot < 1e-6 and pos < 1e-6


def test_translation_least_squares_recovers_a_cubic(rng: np.random.Generator) -> None:
    P = rng.normal(size=(2, 4, 3))
    t = np.tile(np.linspace(0, 1, 25), 2)
    seg = np.repeat([0, 1], 25)
    from mocaplab.staggered import bezier

    y = bezier(P[seg, 0], P[seg, 1], P[seg, 2], P[seg, 3], t)
    a, b = fit_translation_tangents(seg, t, y, P[:, 0], P[:, 3])
    assert np.allclose(P[:, 0] + a, P[:, 1], atol=1e-5)
    assert np.allclose(P[:, 3] + b, P[:, 2], atol=1e-5)


def test_translation_fit_without_samples_is_the_linear_spline() -> None:
    p0, p3 = np.array([[0.0, 0, 0]]), np.array([[3.0, 0, 0]])
    a, b = fit_translation_tangents(np.array([0, 0]), np.array([0.0, 1.0]), np.vstack([p0, p3]), p0, p3)
    assert np.allclose(a, [[1.0, 0, 0]]) and np.allclose(b, [[-1.0, 0, 0]])


def _spherical_samples(n: int = 30):
    q1 = quat.from_axis_angle([0, 0, 1], 0.0)
    q2 = quat.from_axis_angle([1, 0.2, 0], 0.5)
    q3 = quat.from_axis_angle([0.2, 1, 0], 0.4)
    q4 = quat.from_axis_angle([0, 0.5, 1], 0.9)
    t = np.linspace(0, 1, n)
    return q1, q2, q3, q4, t, quat_bezier(q1, q2, q3, q4, t)


def test_appendix_a_objective_terms() -> None:
    q1, q2, q3, q4, t, q = _spherical_samples()
    x = np.concatenate([q2, q3])
    inner = slice(1, -1)
    assert rotation_objective(x, q1, q4, t[inner], q[inner]) == pytest.approx(0.0, abs=1e-12)
    # the unit-length term: | |q2|^2 + |q3|^2 - 2 |
    assert rotation_objective(1.1 * x, q1, q4, t[:0], q[:0]) == pytest.approx(W_C * abs(2 * 1.21 - 2))
    assert W_F == 1000 * W_C


@pytest.mark.parametrize("method", ["gauss-newton", "nelder-mead"])
@pytest.mark.parametrize("start", ["tangent", "linear"])
def test_rotation_tangents_fit_a_spherical_cubic(start: str, method: str) -> None:
    q1, q2, q3, q4, t, q = _spherical_samples()
    seg = np.zeros(t.size, dtype=np.int64)
    alpha, beta, info = fit_rotation_tangents(
        seg, t, q, q1[None], q4[None], start=start, method=method,
        maxiter=3000 if method == "nelder-mead" else 50, polish_tol=0.0,
    )
    # unit (renormalised) tangent quaternions
    assert np.allclose(np.linalg.norm(alpha, axis=-1), 1.0) and np.allclose(np.linalg.norm(beta, axis=-1), 1.0)
    s = quat_bezier(q1, quat.mul(q1, alpha[0]), quat.mul(q4, beta[0]), q4, t)
    err = quat.angle(quat.mul(quat.inv(s), q))
    assert err.max() < np.deg2rad(1.0)
    assert info["error"][0] <= info["start_error"][0] + 1e-12
    if start == "linear":
        # the polish improves substantially on the linear spline it starts from
        assert info["nfev"] > 0 and info["error"][0] < 0.3 * info["start_error"][0]
    with pytest.raises(ValueError, match="method"):
        fit_rotation_tangents(seg, t, q, q1[None], q4[None], method="bfgs")  # type: ignore[arg-type]


def _fit_errors(monkeypatch, m, **options) -> np.ndarray:
    """RMS angle (radians) between the samples and their spline, per rotation segment of ``extract(m)``."""
    from mocaplab.staggered import fit

    seen = []
    real = fit.fit_rotation_tangents

    def spy(seg, tn, q, q1, q4, **kw):
        alpha, beta, info = real(seg, tn, q, q1, q4, **kw)
        seen.append(fit._segment_rms(seg, tn, q, q1, quat.mul(q1, alpha), quat.mul(q4, beta), q4))
        return alpha, beta, info

    monkeypatch.setattr(fit, "fit_rotation_tangents", spy)
    extract(m, **options)
    return seen[-1]


def test_gauss_newton_polish_earns_its_cost(cmu, monkeypatch) -> None:
    """The default polish fits the rotation splines better than the start and than Nelder-Mead, never worse."""
    m = cmu("05_02")[:600]  # a dance: looser segments than a walk's, where the tangent start is already close
    start = _fit_errors(monkeypatch, m, optimize=False)
    polished = _fit_errors(monkeypatch, m)
    nelder = _fit_errors(monkeypatch, m, method="nelder-mead")
    moving = start > 1e-9
    assert np.all(polished <= start + 1e-7)  # per segment: a step is taken only if it helps
    assert polished[moving].mean() < 0.95 * start[moving].mean()
    assert polished[moving].mean() < nelder[moving].mean()


def test_tangent_start_is_close_on_real_data(cmu) -> None:
    """The tangent-space start (the documented speed-up) fits about as well as Nelder-Mead."""
    m = cmu("16_05")
    fast = extract(m, optimize=False)
    slow = extract(m, start="tangent", optimize=True, maxiter=200)
    for sm in (fast, slow):
        rot, pos = reconstruction_error(sm.evaluate(), m)
        assert rot < 1e-6 and pos < 1e-6
    # same poses, refinements and knots: only tangents may differ
    assert np.array_equal(fast.refinements, slow.refinements)
    d_fast = np.linalg.norm(fast.rotation_displacement, axis=-1).mean()
    d_slow = np.linalg.norm(slow.rotation_displacement, axis=-1).mean()
    assert d_slow <= d_fast * 1.05


def test_extract_rejects_bad_input(cmu) -> None:
    with pytest.raises(TypeError, match="Motion"):
        extract(np.zeros((3, 3)))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="max_refinement"):
        extract(cmu("16_05"), max_refinement=-1.0)


def test_random_clips_round_trip() -> None:
    """Property: any clip (random smooth rotations, any frame rate) reconstructs exactly."""
    hyp = pytest.importorskip("hypothesis")
    st = pytest.importorskip("hypothesis.strategies")
    from mocaplab.motion import Motion, Skeleton

    sk = Skeleton(["root", "a", "b", "c"], [-1, 0, 1, 1], [[0, 0, 0], [0, -0.4, 0], [0, -0.4, 0], [0.2, 0, 0]])

    @hyp.settings(max_examples=12, deadline=None)
    @hyp.given(
        n=st.integers(min_value=2, max_value=90),
        fps=st.sampled_from([24.0, 30.0, 60.0, 120.0]),
        seed=st.integers(min_value=0, max_value=2**31 - 1),
        scale=st.floats(min_value=0.0, max_value=3.0),
    )
    def check(n: int, fps: float, seed: int, scale: float) -> None:
        rng = np.random.default_rng(seed)
        steps = rng.normal(scale=scale / np.sqrt(fps), size=(n, 4, 3))
        rot = quat.exp(np.cumsum(steps, axis=0))
        root = np.cumsum(rng.normal(scale=0.05, size=(n, 3)), axis=0)
        m = Motion(sk, rot, root, fps)
        sm = extract(m, contacts=None, maxiter=10)
        out = sm.evaluate()
        assert out.n_frames == n
        assert quat.angle(quat.mul(quat.inv(out.rotations), m.rotations)).max() < 1e-6
        assert np.abs(out.root_positions - m.root_positions).max() < 1e-6
        assert np.abs(sm.refinements).max() <= 0.25 + 1e-12
        T = sm.times[:, None] + sm.refinements
        assert np.all(np.diff(T, axis=0) > 0)

    check()


def test_splines_carry_the_motion_better_than_baselines(cmu) -> None:
    """The fit needs far smaller displacements than the slerp and ease-in/out splines through the same knots."""
    from mocaplab.staggered import fit_representation

    m = cmu("16_15")
    sm = extract(m)
    moving = ~sm.static_joints()

    def median(rep) -> float:
        return float(np.degrees(np.median(np.linalg.norm(rep.rotation_displacement[:, moving], axis=-1))))

    slerp = fit_representation(m, sm.times, sm.refinements, start="linear", optimize=False)
    ease = fit_representation(m, sm.times, sm.refinements, start="ease", optimize=False)
    assert np.allclose(ease.rotation_tangents[..., 3], 1.0)  # identity tangents
    assert median(sm) < 0.5  # degrees: the displacement maps keep small detail
    assert median(sm) < 0.4 * min(median(slerp), median(ease))
    for rep in (slerp, ease):
        rot, pos = reconstruction_error(rep.evaluate(), m)
        assert rot < 1e-6 and pos < 1e-6
    with pytest.raises(ValueError, match="start"):
        fit_representation(m, sm.times, sm.refinements, start="cubic")  # type: ignore[arg-type]


def test_explicit_contacts_without_any_contact_warn(cmu) -> None:
    from mocaplab.contacts import Contacts
    from mocaplab.staggered import NoContactsWarning

    m = cmu("16_05")
    joints = m.skeleton.roles.foot_joints()
    empty = Contacts(joints, np.zeros((m.n_frames, len(joints)), dtype=bool), m.fps)
    with pytest.warns(NoContactsWarning, match="holds nothing"):
        sm = extract(m, contacts=empty, constraints=True, max_poses=6)
    assert not sm.constraints.masks.any()

