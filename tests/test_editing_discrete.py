"""Discrete motion editing (Kim et al. 2009, section 5): transformations, pruning, Algorithm 1."""

from __future__ import annotations

import numpy as np
import pytest

from mocaplab import quat
from mocaplab.contacts import foot_contacts
from mocaplab.editing import (
    AbsoluteTime,
    DiscreteEditor,
    Duration,
    PinDirection,
    PinPosition,
    Relative,
    SceneEditor,
    Sync,
    edit,
)
from mocaplab.editing import discrete as D
from mocaplab.editing.energy import durations, path_lengths
from mocaplab.editing.graph import build_graph, joint_weights
from mocaplab.editing.paths import MotionPath

FPS = 30.0


@pytest.fixture(scope="module")
def walk(mocap_dir):
    from mocaplab import data

    return data.cmu("16_15").resample(FPS)


@pytest.fixture(scope="module")
def track(walk):
    return D.Track.from_motion(walk, build_graph([walk]))


def ground(m):
    return m.root_positions[:, [0, 2]]


def strides(edited, reference):
    """Distances between successive plants of the same foot: plants detected on the undeformed clip."""
    c = foot_contacts(reference)
    out = []
    for foot in ("LeftFoot", "RightFoot"):
        pos = edited.global_positions()[:, edited.skeleton.index(foot)][:, [0, 2]]
        mids = [pos[(a + b) // 2] for a, b in c.intervals(foot) if b - a >= 3]
        out += [float(np.linalg.norm(q - p)) for p, q in zip(mids[:-1], mids[1:], strict=True)]
    return np.array(out)


def big_joints(m):
    return np.flatnonzero(joint_weights(m.skeleton) >= 0.1)


def max_joint_steps(m):
    """Largest frame-to-frame rotation of each main joint (radians)."""
    j = big_joints(m)
    r = m.rotations[:, j]
    return quat.angle(quat.mul(r[1:], quat.inv(r[:-1]))).max(axis=0)


# ----------------------------------------------------------------- applying
def test_track_of_an_unedited_clip(walk, track):
    assert track.n_frames == walk.n_frames
    assert np.array_equal(track.origin, np.arange(walk.n_frames))
    assert track.frame_of(10) == 10 and track.frame_of(walk.n_frames - 1) == walk.n_frames - 1
    with pytest.raises(ValueError, match="no clip with the poses"):
        D.Track.from_motion(walk[:50], track.graph)


def test_deletion_and_duplication_follow_section_5_1(walk, track):
    # a similar pair (i, j): i -> j + 1 deletes i+1..j, j -> i + 1 plays i+1..j twice
    i, j = (int(v) for v in track.graph.pairs[0])
    fps = walk.fps
    dele = D.Transformation(0, "deletion", (i + 1, j + 1), (0, 0), fps)
    t = D.apply_transformation(track, dele)
    assert np.array_equal(t.nodes, np.r_[0 : i + 1, j + 1 : walk.n_frames])
    dup = D.Transformation(0, "duplication", (i + 1, i + 1), (i + 1, j + 1), fps)
    t2 = D.apply_transformation(track, dup)
    assert np.array_equal(t2.nodes, np.r_[0 : j + 1, i + 1 : walk.n_frames])
    # the copy is the earlier instance: frames after the seam keep their identity
    assert np.array_equal(t2.origin[: i + 1], np.arange(i + 1))
    assert np.all(t2.origin[i + 1 : j + 1] == -1)
    assert t2.frame_of(walk.n_frames - 1) == t2.n_frames - 1
    assert t2.frame_of(i + 5) == j + 5
    # the input track is not modified
    assert track.n_frames == walk.n_frames


def test_transformed_motion_has_no_pops(walk, track):
    i, j = (int(v) for v in track.graph.pairs[0])
    dup = D.Transformation(0, "duplication", (i + 1, i + 1), (i + 1, j + 1), walk.fps)
    m = D.apply_transformation(track, dup).motion
    assert m.n_frames == walk.n_frames + (j - i)
    # no joint turns faster across the seam than anywhere in the clip (10% slack)
    assert np.all(max_joint_steps(m) <= 1.1 * max_joint_steps(walk) + 1e-3)
    # the root path and heading continue: no step longer than the clip's longest
    steps = np.linalg.norm(np.diff(ground(m), axis=0), axis=1)
    assert steps.max() <= 1.1 * np.linalg.norm(np.diff(ground(walk), axis=0), axis=1).max()
    yaw = np.unwrap(quat.yaw(m.rotations[:, 0]))
    yaw0 = np.unwrap(quat.yaw(walk.rotations[:, 0]))
    assert np.abs(np.diff(yaw)).max() <= 1.1 * np.abs(np.diff(yaw0)).max() + 1e-3
    # the prefix is untouched, up to the blend window
    n = int(round(0.2 * walk.fps))
    assert np.allclose(m.rotations[: i + 1 - n], walk.rotations[: i + 1 - n])
    # and the time track is the clip's uniform one
    assert m.fps == walk.fps


def test_bad_transformations_are_rejected(walk, track):
    F = walk.n_frames
    with pytest.raises(ValueError, match="1 <= a <= b"):
        D.apply_transformation(track, D.Transformation(0, "deletion", (0, 5), (0, 0), FPS))
    with pytest.raises(ValueError, match="1 <= a <= b"):
        D.apply_transformation(track, D.Transformation(0, "deletion", (5, F), (0, 0), FPS))
    with pytest.raises(ValueError, match="empty"):
        D.apply_transformation(track, D.Transformation(0, "insertion", (5, 5), (3, 3), FPS))


# -------------------------------------------------------------- enumeration
def test_enumerated_transformations_use_graph_transitions(walk, track):
    cands = D.enumerate_transformations(track, character=2)
    assert cands and {t.kind for t in cands} <= set(D.TYPES)
    assert len({(t.removed, t.inserted) for t in cands}) == len(cands)
    gd = track.arrays
    nodes = track.nodes
    for t in cands:
        assert t.character == 2
        a, b = t.removed
        s, e = t.inserted
        assert 1 <= a <= b <= walk.n_frames - 1
        for n in (b - a, e - s):
            assert n == 0 or 0.3 <= n / FPS + 1e-9 and n / FPS <= 2.0 + 1e-9
        if t.kind == "deletion":
            assert s == e and gd.seam_cost(int(nodes[a - 1]), int(nodes[b])) is not None
        else:
            assert gd.seam_cost(int(nodes[a - 1]), s) is not None
            assert gd.seam_cost(e - 1, int(nodes[b])) is not None
        if t.kind == "duplication":
            assert a == b and np.array_equal(nodes[a : a + e - s], np.arange(s, e))
        if t.kind == "replacement":
            assert a < b and s < e and s != nodes[a] and e - 1 != nodes[b - 1]
    kinds = {t.kind for t in cands}
    assert {"deletion", "duplication"} <= kinds


def test_durations_are_configurable(track):
    short = D.enumerate_transformations(track, min_duration=0.3, max_duration=0.8)
    assert all(max(t.removed_duration, t.inserted_duration) <= 0.8 + 1e-9 for t in short)
    assert len(short) < len(D.enumerate_transformations(track, max_duration=2.0))


# ------------------------------------------------------------------ pruning
def T(kind, removed, inserted, character=0):
    return D.Transformation(character, kind, removed, inserted, FPS)


def test_pruning_duration_and_constraints():
    pins = [
        PinPosition(0, 20, (0, 0)),
        PinPosition(0, None, (0, 0), frames=(50, 81)),
        Sync(1, 5, 0, 90),
    ]
    assert D.protected_frames(pins, 0) == {20, 50, 80, 90}
    assert D.protected_frames(pins, 1) == {5}
    ok = T("deletion", (21, 40), (0, 0))
    assert D.pruning_violations(ok, constraints=pins) == ()
    assert D.pruning_violations(T("deletion", (10, 30), (0, 0)), constraints=pins) == ("constraints",)
    # frames inside a variational constraint may go, its boundary frames may not
    assert D.pruning_violations(T("deletion", (55, 75), (0, 0)), constraints=pins) == ()
    assert D.pruning_violations(T("replacement", (70, 85), (200, 215)), constraints=pins) == ("constraints",)
    # insertions remove nothing, even next to a pinned frame
    assert D.pruning_violations(T("insertion", (20, 20), (200, 230)), constraints=pins) == ()
    assert D.pruning_violations(T("deletion", (21, 26), (0, 0))) == ("duration",)  # 0.17 s
    assert D.pruning_violations(T("duplication", (1, 1), (1, 71))) == ("duration",)  # 2.33 s
    kept = D.prune([ok, T("deletion", (10, 30), (0, 0)), T("deletion", (21, 26), (0, 0))], constraints=pins)
    assert kept == [ok]


def test_pruning_enclosing():
    small = T("deletion", (20, 40), (0, 0))
    big = T("deletion", (15, 60), (0, 0))
    other = T("deletion", (30, 70), (0, 0))
    dup_big = T("duplication", (10, 10), (10, 60))
    rep = T("replacement", (20, 40), (100, 130))
    rep_big = T("replacement", (15, 45), (95, 140))
    kept = D.prune([small, big, other, dup_big, rep, rep_big])
    # the enclosing deletion goes (the enclosed one would happen first while dragging);
    # overlapping ones stay, and types are compared separately
    assert big not in kept and rep_big not in kept
    assert {small, other, dup_big, rep} <= set(kept)
    # characters are compared separately too
    assert T("deletion", (15, 60), (0, 0), character=1) in D.prune([small, T("deletion", (15, 60), (0, 0), 1)])


def test_locality():
    t = T("duplication", (30, 30), (30, 60))
    times = np.arange(200) / FPS
    pos = np.c_[np.zeros(200), np.arange(200) * 0.04]
    assert D.Locality().allows(t, times, pos)
    assert not D.Locality(characters=[1]).allows(t, times, pos)
    assert not D.Locality(types=("deletion",)).allows(t, times, pos)
    assert D.Locality(time_zones=[(0.5, 2.5)]).allows(t, times, pos)
    assert not D.Locality(time_zones=[(1.5, 2.5)]).allows(t, times, pos)
    assert D.Locality(regions=[D.Box((-1, 0), (1, 3))]).allows(t, times, pos)
    assert not D.Locality(regions=[D.Disk((0, 3), 0.5)]).allows(t, times, pos)
    assert D.Locality(regions=[D.Disk((0, 3), 0.5), D.Disk((0, 1.8), 1.0)]).allows(t, times, pos)
    assert D.pruning_violations(t, locality=D.Locality(types=["deletion"])) == ("locality",)
    with pytest.raises(ValueError, match="Unknown transformation type"):
        D.Locality(types=("swap",))
    with pytest.raises(ValueError, match="t0 <= t1"):
        D.Locality(time_zones=[(2.0, 1.0)])
    with pytest.raises(TypeError, match="contains"):
        D.Locality(regions=[(0, 0)])
    with pytest.raises(ValueError, match="lo <= hi"):
        D.Box((1, 1), (0, 0))


def test_options_validation():
    with pytest.raises(ValueError, match="min_duration"):
        D.DiscreteOptions(min_duration=3.0)
    with pytest.raises(ValueError, match="subsample"):
        D.DiscreteOptions(subsample=0)
    with pytest.raises(ValueError, match="cs"):
        D.DiscreteOptions(cs=-1)
    loc = D.Locality(types=("deletion",))
    assert D.DiscreteOptions(locality={1: loc}).locality_of(1) is loc
    assert D.DiscreteOptions(locality={1: loc}).locality_of(0) == D.Locality()


# ---------------------------------------------------------------- evaluation
@pytest.fixture(scope="module")
def duo(mocap_dir):
    from mocaplab import data

    a = data.cmu("16_15").resample(FPS)
    b = data.cmu("16_11").resample(FPS).transformed(translation=(1.5, 0, 0))
    pa, pb = MotionPath.from_motion(a), MotionPath.from_motion(b)
    fa, fb = 60, 70
    cons = [
        PinPosition(0, 0, ground(a)[0], hard=True),
        PinPosition(0, a.n_frames - 1, ground(a)[-1] + [0.3, 1.2], hard=True),
        PinDirection(0, 30, pa.tangents[30]),
        PinPosition(1, 0, ground(b)[0], hard=True),
        Relative(1, fb, 0, fa, pa.local_offset(fa, pb.positions[fb])),
        Sync(1, fb, 0, fa, offset=(fb - fa) / FPS, hard=True),
        AbsoluteTime(0, a.n_frames - 1, a.duration + 0.4),
    ]
    return [a, b], cons


def scene_of(chars, cons, **opts):
    ed = SceneEditor(chars, cons)
    tracks = [D.Track.from_motion(m, build_graph([m])) for m in chars]
    sc = D.SubsampledScene(tracks, ed.paths, cons, ed.segments, [0.0] * len(chars), deformed=ed.result.paths, **opts)
    return ed, tracks, sc


def test_evaluation_without_subsampling_matches_the_full_solver(duo):
    # every frame kept: the evaluation's equations are those of section 4, solved with
    # penalties and Woodbury coupling instead of Lagrange multipliers: same energies
    chars, cons = duo
    ed, _, sc = scene_of(chars, cons, subsample=1)
    terms = sc.terms()  # entry 0: the untransformed scene
    assert len(sc.space.rhs) and not sc.space.intra.all()  # a Relative row links the two characters
    res = ed.result
    e = res.energies
    # (the evaluation holds free modes with a tiny regulariser and hard rows with a
    # large weight: differences of order 1e-4 in the absolute terms)
    assert terms["shape"][0] == pytest.approx(e.shape, rel=0.05)
    assert terms["scale"][0] == pytest.approx(e.scale, rel=0.02)
    assert terms["time"][0] == pytest.approx(e.time, rel=0.02, abs=1e-9)
    dl = np.abs(path_lengths(res.paths) - [p.length for p in res.original_paths]).sum()
    dt = np.abs(durations(res.times) - [(p.n_frames - 1) / p.fps for p in res.original_paths]).sum()
    assert terms["length"][0] == pytest.approx(dl, rel=0.02)
    assert terms["duration"][0] == pytest.approx(dt, rel=0.02, abs=1e-3)


def test_subsampled_evaluation_approximates_and_batches(duo):
    chars, cons = duo
    _, tracks, full = scene_of(chars, cons, subsample=1)
    _, _, sub = scene_of(chars, cons)
    assert sub.baseline == pytest.approx(full.baseline, rel=0.1)
    assert sum(len(f) for f in sub.base_frames) < 0.3 * sum(m.n_frames for m in chars)
    every = [t for k in (0, 1) for t in D.enumerate_transformations(tracks[k], character=k)]
    cands = every[:6] + every[-6:]  # both characters
    assert {t.character for t in cands} == {0, 1}
    batched = sub.energies(cands)
    one_by_one = [sub.energy(t) for t in cands]
    # one batch for all characters: a candidate's energy does not depend on the others evaluated with it
    assert np.allclose(batched, one_by_one, rtol=1e-9, atol=1e-12)
    assert np.allclose(sub.energies(cands[::-1]), batched[::-1], rtol=1e-9, atol=1e-12)
    assert sub.terms(cands)["total"][0] == pytest.approx(sub.baseline, rel=1e-9)


def test_rows_too_long_for_a_band_are_coupled(duo):
    # a Duration row spans 90 frames: it cannot sit in a path's banded block, so the
    # evaluation couples it like a row between characters (same energies as the full solver)
    chars, cons = duo
    cons = cons + [Duration(0, 10, 100, 90 / FPS + 0.4, weight=2.0), Duration(1, 5, 60, 55 / FPS - 0.2, hard=True)]
    ed, tracks, full = scene_of(chars, cons, subsample=1)
    terms = full.terms()
    e = ed.result.energies
    assert terms["time"][0] == pytest.approx(e.time, rel=0.02, abs=1e-9)
    assert terms["shape"][0] == pytest.approx(e.shape, rel=0.05)
    _, _, sub = scene_of(chars, cons)
    cands = [t for k in (0, 1) for t in D.prune(D.enumerate_transformations(tracks[k], character=k), constraints=cons)]
    assert {t.character for t in cands} == {0, 1}
    batched = sub.energies(cands)
    assert np.all(np.isfinite(batched))
    assert np.allclose(batched, [sub.energy(t) for t in cands], rtol=1e-9, atol=1e-12)


# --------------------------------------------------------------- Algorithm 1
def stretched(walk, factor):
    P = ground(walk)
    return [
        PinPosition(0, 0, P[0], hard=True),
        PinPosition(0, walk.n_frames - 1, P[0] + factor * (P[-1] - P[0]), hard=True),
    ]


def test_stretching_a_walk_adds_steps_instead_of_longer_strides(walk):
    # Figure 6: drag one end of a pinned walk 50% further, in small steps
    ed = DiscreteEditor([walk], stretched(walk, 1.0))
    assert ed.result.transformations == ()  # nothing to gain before the drag
    P = ground(walk)
    for s in np.linspace(0.05, 0.5, 10):
        res = ed.drag(1, P[0] + (1 + s) * (P[-1] - P[0]))
    assert res.transformations, "steps should have been added"
    assert res.characters[0].n_frames > walk.n_frames + 30
    assert res.hard_residual_space < 1e-6
    base = strides(walk, walk).mean()
    with_discrete = strides(res.edited_motions[0], res.characters[0]).mean()
    plain = edit([walk], stretched(walk, 1.5))
    without = strides(plain.edited_motions[0], walk).mean()
    assert abs(with_discrete / base - 1) < 0.15
    assert without / base - 1 > 0.30
    # one transformation per update at most, each one respecting the pruning rules
    assert len({t.update for t in res.transformations}) == len(res.transformations)
    assert ed.applied == res.transformations
    for h in ed.history:
        t = h.transformation
        assert D.pruning_violations(t, constraints=h.constraints, times=h.times, positions=h.positions) == ()
        assert t.energy < t.baseline and t.full_energy < t.full_baseline
        assert any((c.removed, c.inserted) == (t.removed, t.inserted) for c in h.candidates)


def test_edit_one_shot_matches_the_interactive_result(walk):
    res = edit([walk], stretched(walk, 1.5), discrete=True)
    assert res.transformations
    base = strides(walk, walk).mean()
    assert abs(strides(res.edited_motions[0], res.characters[0]).mean() / base - 1) < 0.15
    assert edit([walk], stretched(walk, 1.5)).transformations == ()  # off by default


def test_stretching_in_time_duplicates_the_idle_part(mocap_dir):
    from mocaplab import data

    m = data.cmu("16_34").resample(FPS)  # slow walk, then stop
    P = ground(m)
    F = m.n_frames
    cons = [
        PinPosition(0, 0, P[0], hard=True),
        PinPosition(0, F - 1, P[-1], hard=True),
        AbsoluteTime(0, 0, 0.0, hard=True),
        AbsoluteTime(0, F - 1, m.duration, hard=True),
    ]
    ed = DiscreteEditor(m, cons)
    for dt in np.linspace(0.15, 1.2, 8):
        res = ed.drag(3, m.duration + dt)
    assert res.transformations
    speed = np.linalg.norm(np.gradient(P, axis=0), axis=1) * FPS
    for t in res.transformations:
        assert t.kind in ("duplication", "insertion")
        s, e = t.inserted
        assert speed[s:e].mean() < 0.3 * speed.mean(), "the stop is duplicated, not the walk"
    # the path keeps its length; the clip gets longer in time
    assert res.characters[0].n_frames > F
    assert abs(res.original_paths[0].length - MotionPath.from_motion(m).length) < 0.1


def test_constraints_follow_their_frames(walk):
    cons = stretched(walk, 1.5) + [PinDirection(0, 100, MotionPath.from_motion(walk).tangents[100])]
    ed = DiscreteEditor([walk], cons)
    res = ed.result
    assert res.transformations and ed.tracks[0].n_frames == res.characters[0].n_frames
    # the editor keeps the input frames; the result holds them mapped to the current frames
    assert ed.constraints == tuple(cons)
    mapped = res.constraints
    assert mapped[1].frame == res.characters[0].n_frames - 1
    assert mapped[2].frame == ed.tracks[0].frame_of(100)
    assert np.allclose(res.paths[0][mapped[1].frame], cons[1].position, atol=1e-6)
    # the transformed clip's frames at the constraint show the same pose as the input
    f = mapped[2].frame
    assert np.allclose(res.characters[0].rotations[f, 1:], walk.rotations[100, 1:], atol=1e-6)


def test_locality_can_switch_discrete_editing_off(walk):
    opts = D.DiscreteOptions(locality=D.Locality(types=()))
    assert edit([walk], stretched(walk, 1.5), discrete=opts).transformations == ()
    opts = D.DiscreteOptions(locality=D.Locality(types=("deletion",)))
    assert edit([walk], stretched(walk, 1.5), discrete=opts).transformations == ()
    # shrinking calls for deletions
    res = edit([walk], stretched(walk, 0.6), discrete=opts)
    assert res.transformations and all(t.kind == "deletion" for t in res.transformations)


def test_option_errors(walk):
    with pytest.raises(TypeError, match="DiscreteOptions"):
        DiscreteEditor([walk], stretched(walk, 1.0), discrete="yes")
    with pytest.raises(TypeError, match="continuous-only.*DiscreteEditor"):
        SceneEditor([walk], stretched(walk, 1.0), discrete=True)
    with pytest.raises(TypeError, match="Unknown option"):
        DiscreteEditor([walk], stretched(walk, 1.0), nope=1)


# ------------------------------------------------------------- linear in characters
def relay(a, b, groups):
    """Lesson 05's relay: high-five pairs (a walks, b faces it), each group starting where the last ends."""
    pa = ground(a)
    heading = np.arctan2(*(ground(b)[-1] - ground(b)[0]))
    b = b.transformed(yaw=np.pi - heading)
    FA, FB = a.n_frames, b.n_frames
    fa, fb = 60, FB // 2
    pb = ground(b)
    b = b.transformed(translation=(pa[fa, 0] + 0.6 - pb[fb, 0], 0.0, pa[fa, 1] - pb[fb, 1]))
    step = pa[-1] - pa[0] + np.array([0.0, 0.8])
    chars, cons = [], [AbsoluteTime(0, 0, 0.0, hard=True)]
    for g in range(groups):
        shift = (g * step[0], 0.0, g * step[1])
        chars += [a.transformed(translation=shift), b.transformed(translation=shift)]
        A, B = 2 * g, 2 * g + 1
        cons += [Relative(B, fb, A, fa, (0.0, 0.6), direction=np.pi, hard=True), Sync(B, fb, A, fa, hard=True)]
        if g:
            cons += [Relative(A, 0, A - 2, FA - 1, (0.8, 0.0), direction=0.0, hard=True), Sync(A, 0, A - 2, FA - 1, offset=a.dt, hard=True)]
    cons += [PinPosition(2 * g, 0, ground(chars[2 * g])[0]) for g in range(groups)]
    cons += [PinPosition(2 * groups - 2, FA - 1, ground(chars[-2])[-1] + [0.0, 0.5])]
    return chars, cons


def candidates(tracks, cons):
    """Every pruned candidate transformation of every character."""
    return [t for k, tr in enumerate(tracks) for t in D.prune(D.enumerate_transformations(tr, character=k), constraints=cons)]


@pytest.fixture(scope="module")
def relays(walk, mocap_dir):
    from mocaplab import data

    b = data.cmu("02_01").resample(FPS)
    out = {}
    for groups in (3, 6):
        chars, cons = relay(walk, b, groups)
        ed = SceneEditor(chars, cons)
        tracks = [D.Track.from_motion(m, build_graph([m])) for m in chars]
        cands = candidates(tracks, cons)
        out[groups] = (ed, tracks, cons, cands)
    return out


def test_evaluation_memory_grows_linearly_with_characters(relays):
    import tracemalloc

    peaks, sizes = {}, {}
    for groups, (ed, tracks, cons, cands) in relays.items():
        sc = D.SubsampledScene(tracks, ed.paths, cons, ed.segments, [0.0] * len(tracks), deformed=ed.result.paths)
        parts = sc.parts(cands)
        S = sc.systems(parts)
        sizes[groups] = (S.space.U.shape[1], S.time.U.shape[1])  # coupled rows per character: not per scene
        tracemalloc.start()
        sc.terms(cands)
        peaks[groups] = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert sizes[3] == sizes[6], "each part couples to the rows of its own character only"
    # twice the characters (and candidates): a linear evaluation takes about twice the memory
    # (the cubic one before it took 8x: it built (variants x characters x unknowns x coupled rows) arrays)
    assert peaks[6] / peaks[3] < 3.0, peaks


def test_far_parts_keep_their_energies_within_a_small_fraction_of_min_gain(relays):
    # parts a candidate moves by less than FAR (1 mm) keep their base energies: measured errors 2e-4,
    # 1/500 of min_gain (the gain a transformation must bring)
    ed, tracks, cons, cands = relays[6]
    kw = dict(deformed=ed.result.paths)
    exact = D.SubsampledScene(tracks, ed.paths, cons, ed.segments, [0.0] * len(tracks), far=0.0, **kw).terms(cands)
    fast = D.SubsampledScene(tracks, ed.paths, cons, ed.segments, [0.0] * len(tracks), **kw).terms(cands)
    for key in exact:
        np.testing.assert_allclose(fast[key], exact[key], atol=5e-3 * D.DiscreteOptions().min_gain, err_msg=key)
    assert np.argmin(fast["total"][1:]) == np.argmin(exact["total"][1:])
    # and the exact evaluation is what a one-by-one evaluation gives
    sc = D.SubsampledScene(tracks, ed.paths, cons, ed.segments, [0.0] * len(tracks), far=0.0, **kw)
    one = [sc.energy(t) for t in cands[:: max(1, len(cands) // 6)]]
    np.testing.assert_allclose(one, exact["total"][1:][:: max(1, len(cands) // 6)], rtol=1e-9, atol=1e-12)


# ------------------------------------------------- sparse per-candidate updates
def dense_reference(sc, cands):
    """Equation 10 of every variant, straightforwardly: one variant at a time, every part of it solved.

    Each variant's coupled system ``(I + sum U Z) w = c - sum U y`` is assembled densely over every
    part and solved on its own (no Woodbury update of the base scene, no bound, no first-order
    term); every part's move is computed, the coupled residuals are ``U x - c``, and the length
    and duration terms are evaluated exactly for every part.  What the evaluation may leave out
    it leaves out here too: a part moved (translation aside, for parts whose own rows ignore it)
    by no more than ``far`` keeps its base energies, and phase 2 starts from phase 1's solution
    of the parts that moved.  The per-part terms are the evaluation's own (``PartTerms``).
    """
    from mocaplab.editing.discrete.evaluation import PartTerms

    p = sc.parts(cands)
    S = sc.systems(p)
    T = PartTerms(S)
    K, C = sc.K, len(cands)

    def invariant(loc, dim):  # parts whose own rows all ignore a translation
        sums = [np.sum(np.where(loc.cols[:K] % dim == c, loc.vals[:K], 0.0), axis=2) for c in range(dim)]
        scale = np.abs(loc.vals[:K]).sum(axis=2) + 1e-300
        return np.all([np.all(np.abs(s) <= 1e-12 * scale, axis=1) for s in sums], axis=0)

    def solve(cp, members, y, Z):
        g = cp.g
        N, r, held = np.eye(g + 1), np.zeros(g + 1), np.zeros(g + 1, bool)
        for q, yq in zip(members, y, strict=True):
            rows = cp.of_char[p.char[q]]
            np.add.at(N, (rows[:, None], rows[None, :]), cp.U[q] @ Z[q])
            np.add.at(r, rows, -cp.U[q] @ yq)
            held[rows[cp.held[q]]] = True
        c = np.where(held[:g], cp.rhs, 0.0)
        r[:g] += c
        N[g, :], N[:, g], N[g, g], r[g] = 0.0, 0.0, 1.0, 0.0
        w = np.linalg.solve(N, r)
        x = np.array([yq + Z[q] @ w[cp.of_char[p.char[q]]] for q, yq in zip(members, y, strict=True)])
        Ux = np.zeros(g + 1)
        for q, xq in zip(members, x, strict=True):
            np.add.at(Ux, cp.of_char[p.char[q]], cp.U[q] @ xq)
        return x, np.sum(np.where(cp.soft, Ux[:g] - c, 0.0) ** 2)

    def moved(dx, k, dim, inv):
        d = dx.reshape(-1, dim)
        if inv[k]:
            v = S.valid[k]
            d = np.where(v[:, None], d - d[v].mean(axis=0), 0.0)
        return np.abs(d).max() > sc.far

    inv_s, inv_t = invariant(S.s_loc, 2), invariant(S.t_loc, 1)
    out = {key: np.zeros(1 + C) for key in ("shape", "scale", "time", "length", "duration")}
    base = {}
    for v in range(1 + C):
        members = np.arange(K)
        if v:
            members[p.char[K + v - 1]] = K + v - 1
        one = [np.array([q]) for q in members]
        own = members >= K  # the candidate's part
        x1, e1 = solve(S.space, members, S.shape.y[members], S.shape.Z)
        xt, et = solve(S.time, members, S.time_blocks.y[members], S.time_blocks.Z)
        if v == 0:
            base = {"x1": x1, "xt": xt}
        m1 = own | [moved(x1[k] - base["x1"][k], k, 2, inv_s) for k in range(K)]
        x1_used = np.where(m1[:, None], x1, base["x1"])
        targets = [T.scale_targets(q, x[None]) for q, x in zip(one, x1_used, strict=True)]
        y2 = np.array([T.solve_scale(q, rhs)[0] for q, (rhs, _) in zip(one, targets, strict=True)])
        x2, e2 = solve(S.space, members, y2, S.scale.Z)
        if v == 0:
            base["x2"] = x2
        m2 = m1 | [moved(x2[k] - base["x2"][k], k, 2, inv_s) for k in range(K)]
        mt = own | [moved(xt[k] - base["xt"][k], k, 1, inv_t) for k in range(K)]
        for k, q in enumerate(one):
            a1 = x1[k] if m1[k] else base["x1"][k]
            a2 = x2[k] if m2[k] else base["x2"][k]
            at = xt[k] if mt[k] else base["xt"][k]
            out["shape"][v] += T.shape(q, a1[None])[0]
            out["scale"][v] += T.scale(q, a2[None], targets[k][1])[0]
            out["time"][v] += T.time(q, at[None])[0]
            out["length"][v] += abs(T.length_change(q, x2[k][None])[0])
            out["duration"][v] += abs(T.duration_change(q, xt[k][None])[0])
        out["shape"][v] += e1
        out["scale"][v] += e2
        out["time"][v] += et
    out["total"] = out["shape"] + out["scale"] + out["time"] + sc.cs * out["length"] + sc.ct * out["duration"]
    return out


@pytest.fixture(scope="module")
def long_relay(mocap_dir):
    """Three groups of the relay with its clips resampled at 80 fps (314 and 229 frames), the end pin pulled."""
    from mocaplab import data

    a, b = data.cmu("16_15").resample(80.0), data.cmu("02_01").resample(80.0)
    chars, cons = relay(a, b, 3)
    ed = SceneEditor(chars, cons)
    tracks = [D.Track.from_motion(m, build_graph([m])) for m in chars]
    return ed, tracks, cons, candidates(tracks, cons)


@pytest.fixture(scope="module")
def soft_ties(relays):
    """The three-group relay with soft ties between the groups too (soft coupled rows: their residuals are energy)."""
    _, tracks, cons, _ = relays[3]
    chars = [t.motion for t in tracks]
    paths = [MotionPath.from_motion(m) for m in chars]
    f = chars[1].n_frames // 2
    ties = [
        Relative(3, f, 1, f, np.add(paths[1].local_offset(f, paths[3].positions[f]), [0.1, 0.0]), weight=2.0),
        Sync(5, f, 3, f, offset=0.2),
    ]
    cons = cons + ties
    return SceneEditor(chars, cons), tracks, cons, candidates(tracks, cons)


@pytest.mark.parametrize(("scene", "far"), [(3, None), (6, None), (6, 0.0), ("long", None), ("soft", None)])
def test_sparse_variants_equal_a_dense_evaluation_of_each_variant(
    relays, long_relay, soft_ties, monkeypatch, scene, far
):
    from mocaplab.editing.discrete import evaluation as E

    ed, tracks, cons, cands = {"long": long_relay, "soft": soft_ties}.get(scene) or relays[scene]
    kw = {} if far is None else {"far": far}
    sc = D.SubsampledScene(tracks, ed.paths, cons, ed.segments, [0.0] * len(tracks), deformed=ed.result.paths, **kw)
    # count the part-variant pairs whose moves the length and duration terms expand
    summed, expanded, inside = [], [], []
    moves, over_parts = E.PhaseSolution.moves, E._sum_over_parts

    def counting_sum(sol, *args):
        inside.append(1)
        summed.append(sol.dw.shape[0] * sol.dw.shape[1])
        try:
            return over_parts(sol, *args)
        finally:
            inside.pop()

    monkeypatch.setattr(
        E.PhaseSolution, "moves", lambda self, k, c: (inside and expanded.append(len(k))) or moves(self, k, c)
    )
    monkeypatch.setattr(E, "_sum_over_parts", counting_sum)
    fast = sc.terms(cands)
    monkeypatch.undo()
    ref = dense_reference(sc, cands)
    for key in ref:
        np.testing.assert_allclose(fast[key], ref[key], rtol=1e-9, atol=1e-9, err_msg=key)
    # the same choice: the same order of the best candidates, the same set that beats the scene by min_gain
    best = np.argsort(ref["total"][1:], kind="stable")[:5]
    np.testing.assert_array_equal(np.argsort(fast["total"][1:], kind="stable")[:5], best)
    gain = D.DiscreteOptions().min_gain
    assert set(np.flatnonzero(fast["total"][1:] < fast["total"][0] - gain)) == set(
        np.flatnonzero(ref["total"][1:] < ref["total"][0] - gain)
    )
    print(f"{len(tracks)} characters, {len(cands)} candidates: {sum(expanded)} of {sum(summed)} moves expanded")
    assert len(summed) == 2 and sum(expanded) < 0.8 * sum(summed), "the first-order shortcut is taken (and checked)"


@pytest.mark.parametrize("n", [5, 400])  # below and above the size where the products are written out dense
def test_the_sparse_products_equal_their_dense_forms(n):
    from mocaplab.editing.discrete import evaluation as E

    rng = np.random.default_rng(n)
    g = n // 2 + 3
    X = rng.normal(size=(g, g))
    rows = np.concatenate([np.repeat(np.arange(n), 4), rng.integers(0, n, 3 * n)])  # two runs, repeated entries
    cols, vals = rng.integers(0, g, len(rows)), rng.normal(size=len(rows))
    M = np.zeros((n, g))
    np.add.at(M, (rows, cols), vals)
    np.testing.assert_allclose(E._sparse_times(rows, cols, vals, n, X), M @ X, rtol=1e-12, atol=1e-12)
    A, k, w = rng.normal(size=(7, 30, 12)), rng.integers(0, 7, n), rng.normal(size=(n, 12))
    np.testing.assert_allclose(E._products(A, k, w), np.einsum("nmr,nr->nm", A[k], w), rtol=1e-12, atol=1e-12)
