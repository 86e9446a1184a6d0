"""Constraint objects (Kim et al. 2009, sections 3.1 and 3.2) and their validation."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mocaplab.editing import (
    AbsoluteTime,
    ConstraintError,
    Duration,
    PinDirection,
    PinPosition,
    Relative,
    SceneEditor,
    Sync,
    edit,
)


def test_constructors_take_character_first():
    p = PinPosition(1, 10, (1.0, 2.0), hard=True)
    assert (p.character, p.frame, p.position, p.hard, p.weight) == (1, 10, (1.0, 2.0), True, 1.0)
    d = PinDirection(0, 5, np.pi / 2)
    assert d.direction == pytest.approx((1.0, 0.0))  # yaw angle -> unit (x, z)
    assert PinDirection(0, 5, (0.0, 3.0)).direction == (0.0, 1.0)
    r = Relative(0, 3, 1, 4, (0.5, -1.0), direction=0.0)
    assert r.characters == (0, 1) and r.direction == pytest.approx((0.0, 1.0))
    assert AbsoluteTime(0, 2, 1.5).time == 1.5
    assert Duration(0, 2, 20, 1.0).duration == 1.0
    s = Sync(0, 2, 1, 7, offset=0.25)
    assert s.offset == 0.25 and s.characters == (0, 1)


def test_frozen_and_with_target():
    p = PinPosition(0, 10, (1.0, 2.0))
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.frame = 3  # type: ignore[misc]
    q = p.with_target((3.0, 4.0))
    assert q.position == (3.0, 4.0) and p.position == (1.0, 2.0)
    assert q.structure() == p.structure()  # a drag keeps the matrix
    r = Relative(0, 3, 1, 4, (0.5, 0.0))
    assert r.with_target((1.0, 0.0)).structure() != r.structure()  # offsets live in the matrix
    assert Sync(0, 1, 1, 1).with_target(0.5).offset == 0.5
    assert Duration(0, 1, 9, 1.0).with_target(2.0).duration == 2.0
    assert AbsoluteTime(0, 1, 1.0).target == 1.0


def test_variational_samples_every_tenth_frame():
    p = PinPosition(0, None, (0.0, 0.0), frames=(5, 32))
    assert p.variational
    assert p.samples() == [(5,), (15,), (25,), (32,)]
    r = Relative(0, None, 1, None, (1.0, 0.0), frames=(0, 20), other_frames=(100, 140))
    assert r.samples() == [(0, 100), (10, 120), (20, 140)]
    s = Sync(0, None, 1, None, frames=(0, 20))
    assert s.samples() == [(0, 0), (10, 10), (20, 20)]


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: PinPosition(0, None, (0, 0), frames=(10, 10)), "Degenerate interval"),
        (lambda: PinPosition(0, None, (0, 0)), "give `frame`"),
        (lambda: PinPosition(0, 1, (0, 0), frames=(1, 5)), "not both"),
        (lambda: PinPosition(0, -1, (0, 0)), "`frame` >= 0"),
        (lambda: PinPosition(0, 1, (0, np.nan)), "position"),
        (lambda: PinPosition(0, 1, (0, 0), weight=0.0), "weight"),
        (lambda: PinDirection(0, 1, (0.0, 0.0)), "non-zero"),
        (lambda: Duration(0, 10, 10, 1.0), "Degenerate interval"),
        (lambda: Duration(0, 1, 10, -1.0), "duration"),
        (lambda: Sync(0, 4, 0, 4), "itself"),
        (lambda: Relative(0, 4, 1, None, (0, 0)), "other_frame"),
    ],
)
def test_bad_constraints_are_named(make, message):
    with pytest.raises((ValueError, TypeError), match=message):
        make()


def test_character_index_type():
    with pytest.raises(TypeError, match="character"):
        PinPosition("a", 1, (0, 0))  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def walks(mocap_dir):
    from mocaplab import data

    return [data.cmu("16_15").resample(30), data.cmu("02_01").resample(30)]


def test_scene_errors_name_the_constraint(walks):
    n = walks[0].n_frames
    with pytest.raises(ValueError, match=rf"constraint #1 .*frame {n + 5} out of range for character 0"):
        edit(walks, [PinPosition(0, 0, (0, 0)), PinPosition(0, n + 5, (0, 0))])
    with pytest.raises(ValueError, match="constraint #0 .*unknown character 2"):
        edit(walks, [Sync(0, 3, 2, 3)])
    with pytest.raises(TypeError, match="constraint #0"):
        edit(walks, ["pin"])


def test_conflicting_hard_constraints_raise_naming_them(walks):
    p0 = tuple(walks[0].root_positions[10, [0, 2]])
    cons = [
        PinPosition(0, 0, p0, hard=True),
        PinPosition(1, 4, (0.0, 0.0)),
        PinPosition(0, 10, p0, hard=True),
        PinPosition(0, 10, (p0[0] + 1, p0[1]), hard=True),
    ]
    with pytest.raises(ConstraintError) as info:
        edit(walks, cons)
    assert info.value.indices == (2, 3)
    assert "#2" in str(info.value) and "#3" in str(info.value) and "#0" not in str(info.value)
    times = [
        AbsoluteTime(1, 10, 0.0, hard=True),
        AbsoluteTime(1, 20, 1.0, hard=True),
        Duration(1, 10, 20, 2.0, hard=True),
    ]
    with pytest.raises(ConstraintError) as info:
        edit(walks, times)
    assert info.value.indices == (0, 1, 2)
    # a hard relative placement against the same hard pin twice is redundant too
    rel = [
        PinPosition(0, 30, p0, hard=True),
        Relative(1, 5, 0, 30, (0.0, 0.0), hard=True),
        Relative(1, 5, 0, 30, (0.0, 0.0), hard=True),
    ]
    with pytest.raises(ConstraintError) as info:
        edit(walks, rel)
    assert info.value.indices == (1, 2)


def test_hard_constraints_against_time_step_bounds(walks):
    # 100 frames squeezed into 0.1 s needs steps below h_min
    with pytest.raises(ConstraintError, match="time steps within"):
        edit(walks, [AbsoluteTime(0, 0, 0.0, hard=True), AbsoluteTime(0, 100, 0.1, hard=True)])


def test_editor_keeps_state_after_error(walks):
    p = walks[0].root_positions[:, [0, 2]]
    ed = SceneEditor(walks, [PinPosition(0, 0, p[0], hard=True), PinPosition(0, 50, p[50])])
    before = ed.result
    with pytest.raises(ConstraintError):
        ed.add(PinPosition(0, 0, p[0] + 1, hard=True))
    assert len(ed.constraints) == 2
    again = ed.drag(1, p[50] + [0.3, 0.0])
    ref = edit(walks, [PinPosition(0, 0, p[0], hard=True), PinPosition(0, 50, p[50] + [0.3, 0.0])])
    np.testing.assert_allclose(again.paths[0], ref.paths[0], atol=1e-9)
    assert before.paths[0] is not again.paths[0]


def test_rank_screen_agrees_with_the_exact_rank():
    # the sparse Cholesky screen only clears full-row-rank hard rows; anything else goes to the SVD search
    import scipy.sparse as sp

    from mocaplab.editing.laplacian import full_row_rank_screen

    rng = np.random.default_rng(3)
    for _ in range(20):
        m, n = rng.integers(2, 40), rng.integers(40, 80)
        H = sp.random(m, n, density=0.15, random_state=rng, format="csr") + sp.eye(m, n, format="csr")
        dense = H.toarray()
        assert full_row_rank_screen(H) == (np.linalg.matrix_rank(dense) == m)
        # a row that is a combination of two others, a repeated row, an empty row, too many rows
        i, j = rng.choice(m, 2, replace=False)
        for bad in (
            np.vstack([dense, 2.0 * dense[i] - 0.5 * dense[j]]),
            np.vstack([dense, dense[i]]),
            np.vstack([dense, np.zeros(n)]),
            np.vstack([dense, rng.standard_normal((n, n))]),
        ):
            assert not full_row_rank_screen(sp.csr_matrix(bad))


def test_hard_pins_over_constraining_a_rigid_segment_are_named(walks):
    # a stationary segment moves as a similarity in phase 1 (4 modes): two hard pins fix it, a third is redundant
    w = walks[0]
    P = w.root_positions[:, [0, 2]]
    cons = [PinPosition(0, 12, P[12], hard=True)] + [PinPosition(0, f, P[f], hard=True) for f in (15, 25, 35)]
    with pytest.raises(ConstraintError, match="rigid stationary segment") as info:
        edit([w], cons, stationary=[[(10, 40)]], scale_compensation=False)
    assert info.value.indices == (0, 1, 2)  # a minimal dependent set, with the segment
    ok = edit([w], cons[:2], stationary=[[(10, 40)]], scale_compensation=False)
    assert ok.hard_residual_space < 1e-6
