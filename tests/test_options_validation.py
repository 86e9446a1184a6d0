"""Every option of the public entry points is checked before any work (issue 27 item 4, issue 25's validation gaps).

One validator per entry point, all built on :mod:`mocaplab._checks`: a bad
option is a TypeError (wrong kind) or a ValueError (NaN, infinite, out of
range) whose message names the option and says what it takes.  "Before any
work" is tested by sabotage: the first real step of each entry point
(contact detection, pose analysis, role inference, path building, the
solver) is replaced by a function that raises :class:`WorkStarted`, so a
check that comes too late, or not at all, fails the test.  The valid edge
values (0, the bounds themselves, a quaternion of length 2) still work.

The widgets' one error display (:func:`mocaplab.widgets._controls.error_html`)
cannot fail itself and is what the editors and the 3D viewer show.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

import mocaplab as ml
from mocaplab import _checks, goals
from mocaplab.contacts import foot_contacts
from mocaplab.editing import PinPosition, SceneEditor, edit, make_editor, refinement, scene
from mocaplab.physics import state as touchup_state
from mocaplab.staggered import StaggeredEditor, extract
from mocaplab.staggered import edit as staggered_edit
from mocaplab.staggered import fit as staggered_fit

NAN, INF = float("nan"), float("inf")
SOLVE = goals.solve_goals  # the real one: the sabotage below replaces goals.solve_goals, enforce_goals' first step


class WorkStarted(Exception):
    """Raised by a sabotaged first step: an option reached the work unchecked."""


def _boom(*_args, **_kwargs):
    raise WorkStarted("the work started before the options were checked")


@pytest.fixture(scope="module")
def walk(cmu):
    return cmu("16_15")[:120]


@pytest.fixture
def no_work(monkeypatch):
    """The first step of every entry point raises WorkStarted."""
    monkeypatch.setattr(refinement, "resolve_contacts", _boom)  # refine, refine_scene
    monkeypatch.setattr(refinement, "world_targets", _boom)
    monkeypatch.setattr(goals, "_solve_goals", _boom)  # solve_goals
    monkeypatch.setattr(goals, "solve_goals", _boom)  # enforce_goals' first step
    monkeypatch.setattr(staggered_fit, "analyze", _boom)  # extract
    monkeypatch.setattr(staggered_fit, "resolve_roles", _boom)
    monkeypatch.setattr(staggered_edit, "_variables_mask", _boom)  # randomize
    monkeypatch.setattr(staggered_edit, "apply_knot_deltas", _boom)  # edit_pose
    monkeypatch.setattr(touchup_state, "resolve_roles", _boom)  # touch_up / start
    monkeypatch.setattr(touchup_state, "_edge_width", _boom)
    monkeypatch.setattr(scene, "with_roles", _boom)  # edit / SceneEditor / make_editor
    monkeypatch.setattr(scene.MotionPath, "from_motion", _boom)


# (label, call(motion, goals), exception, message pattern)
CORE = [
    # Kim s4.3 refinement and the shared goal layer
    ("refine levels=nan", lambda m, g: ml.refine(m, levels=NAN), ValueError, r"`levels` to be an integer in \[1, 16\].*got nan"),
    ("refine levels=0", lambda m, g: ml.refine(m, levels=0), ValueError, r"`levels` to be an integer in \[1, 16\].*got 0"),
    ("refine levels=-1", lambda m, g: ml.refine(m, levels=-1), ValueError, r"`levels` .*got -1"),
    ("refine levels=2.5", lambda m, g: ml.refine(m, levels=2.5), ValueError, r"`levels` to be an integer.*got 2\.5"),
    ("refine levels=10**6", lambda m, g: ml.refine(m, levels=10**6), ValueError, r"`levels` .*\[1, 16\]"),
    ("refine levels='3'", lambda m, g: ml.refine(m, levels="3"), TypeError, r"`levels` to be an integer.*got str '3'"),
    ("refine spacing=0", lambda m, g: ml.refine(m, spacing=0), ValueError, r"`spacing` > 0 seconds, got 0"),
    ("refine spacing=nan", lambda m, g: ml.refine(m, spacing=NAN), ValueError, r"`spacing` > 0 seconds, got nan"),
    ("refine spacing=inf", lambda m, g: ml.refine(m, spacing=INF), ValueError, r"`spacing` > 0 seconds, got inf"),
    ("refine blend=-1", lambda m, g: ml.refine(m, blend=-1), ValueError, r"`blend` >= 0 seconds, got -1"),
    ("refine blend=nan", lambda m, g: ml.refine(m, blend=NAN), ValueError, r"`blend` >= 0 seconds, got nan"),
    ("refine blend=None", lambda m, g: ml.refine(m, blend=None), TypeError, r"`blend` to be a real number"),
    ("refine_scene levels=nan", lambda m, g: refinement.refine_scene([m], levels=NAN), ValueError, r"`levels`"),
    ("refine_scene spacing=0", lambda m, g: refinement.refine_scene([m], spacing=0), ValueError, r"`spacing` > 0"),
    ("solve_goals reach=nan", lambda m, g: SOLVE(m, g, reach=NAN), ValueError, r"`reach` in \(0, 1\]"),
    ("solve_goals reach=0", lambda m, g: SOLVE(m, g, reach=0), ValueError, r"`reach` in \(0, 1\]"),
    ("solve_goals max_reach=2", lambda m, g: SOLVE(m, g, max_reach=2), ValueError, r"`max_reach`"),
    ("solve_goals max_drop=-1", lambda m, g: SOLVE(m, g, max_drop=-1), ValueError, r"`max_drop` >= 0 metres"),
    ("solve_goals max_drop=nan", lambda m, g: SOLVE(m, g, max_drop=NAN), ValueError, r"`max_drop`"),
    ("solve_goals drop_window=nan", lambda m, g: SOLVE(m, g, drop_window=NAN), ValueError,
     r"`drop_window` in \[0, 10\] seconds"),
    ("solve_goals drop_window=1e308", lambda m, g: SOLVE(m, g, drop_window=1e308), ValueError,
     r"`drop_window` in \[0, 10\]"),
    ("enforce_goals spacing=0", lambda m, g: goals.enforce_goals(m, g, spacing=0), ValueError, r"`spacing` > 0"),
    ("enforce_goals levels=nan", lambda m, g: goals.enforce_goals(m, g, levels=NAN), ValueError, r"`levels`"),
    # Coleman: extraction and the edits
    ("extract max_poses=nan", lambda m, g: extract(m, max_poses=NAN), ValueError,
     r"`max_poses` to be an integer in \[2, 120\].*got nan"),
    ("extract max_poses=0", lambda m, g: extract(m, max_poses=0), ValueError, r"`max_poses` .*\[2, 120\].*got 0"),
    ("extract max_poses=-3", lambda m, g: extract(m, max_poses=-3), ValueError, r"`max_poses` .*got -3"),
    ("extract max_poses=2.5", lambda m, g: extract(m, max_poses=2.5), ValueError, r"`max_poses` .*got 2\.5"),
    ("extract max_poses=10**6", lambda m, g: extract(m, max_poses=10**6), ValueError, r"`max_poses` .*\[2, 120\]"),
    ("extract fraction=nan", lambda m, g: extract(m, fraction=NAN), ValueError, r"`fraction` in \[0, 1\]"),
    ("extract max_refinement=nan", lambda m, g: extract(m, max_refinement=NAN), ValueError, r"`max_refinement`"),
    # Shin: physical touch-up
    ("touch_up schedule=5", lambda m, g: ml.touch_up(m, schedule=5), TypeError,
     r"`schedule` 'default', 'ground', 'flight', 'both', an Adjustment or a non-empty sequence of Adjustment, got int 5"),
    ("touch_up schedule=[5]", lambda m, g: ml.touch_up(m, schedule=[5]), TypeError,
     r"`schedule\[0\]` to be an Adjustment, got int 5"),
    ("touch_up schedule='fly'", lambda m, g: ml.touch_up(m, schedule="fly"), ValueError, r"`schedule` .*got 'fly'"),
    ("touch_up iterations=-1", lambda m, g: ml.touch_up(m, iterations=-1), ValueError,
     r"`iterations` to be an integer >= 0 .*got -1"),
    ("touch_up iterations=nan", lambda m, g: ml.touch_up(m, iterations=NAN), ValueError, r"`iterations` .*got nan"),
    ("touch_up iterations=2.5", lambda m, g: ml.touch_up(m, iterations=2.5), ValueError, r"`iterations` .*got 2\.5"),
    ("touch_up tol=nan", lambda m, g: ml.touch_up(m, tol=NAN), ValueError, r"`tol` >= 0 .*got nan"),
    ("touch_up flight_window=nan", lambda m, g: ml.touch_up(m, flight_window=NAN), ValueError,
     r"`flight_window` in \[0, 10\] seconds, got nan"),
    ("touch_up flight_window=-1", lambda m, g: ml.touch_up(m, flight_window=-1), ValueError,
     r"`flight_window` .*got -1"),
    ("touch_up flight_window=1e308", lambda m, g: ml.touch_up(m, flight_window=1e308), ValueError,
     r"`flight_window` .*got 1e\+308"),
    ("touch_up inertia='rigid'", lambda m, g: ml.touch_up(m, inertia="rigid"), ValueError,
     r'`inertia` to be "points" \(the paper\'s point masses\) or "segments" .*got \'rigid\''),
    ("touch_up inertia=None", lambda m, g: ml.touch_up(m, inertia=None), ValueError, r"`inertia` .*got None"),
]

PIN = [PinPosition(0, 0, (0.0, 0.0), hard=True)]
EDIT_OPTIONS = [
    ({"start_times": [NAN]}, ValueError, r"`start_times\[0\]` to be a finite number of seconds, got nan"),
    ({"start_times": 0.0}, TypeError, r"`start_times` to be a sequence of seconds"),
    ({"variational_step": NAN}, ValueError, r"`variational_step` to be an integer >= 1 \(frames\), got nan"),
    ({"variational_step": 0}, ValueError, r"`variational_step` .*got 0"),
    ({"variational_step": -1}, ValueError, r"`variational_step` .*got -1"),
    ({"flip_window": INF}, ValueError, r"`flip_window` in \[0, 10\] seconds \(at most 10 times the scene's duration\)"),
    ({"flip_window": NAN}, ValueError, r"`flip_window` .*got nan"),
    ({"relative_iterations": -1}, ValueError, r"`relative_iterations` to be an integer >= 1 .*got -1"),
    ({"relative_iterations": 2.5}, ValueError, r"`relative_iterations` .*got 2\.5"),
    ({"relative_tolerance": NAN}, ValueError, r"`relative_tolerance` >= 0 metres"),
    ({"min_step": 0.0}, ValueError, r"`min_step` in \(0, 1\)"),
    ({"max_step": INF}, ValueError, r"`max_step` > 1"),
    ({"stationary_speed": "fast"}, TypeError, r"`stationary_speed` to be a real number >= 0 m/s, got str 'fast'"),
]
ENTRIES = {
    "edit": lambda m, constraints, **o: edit([m], constraints, **o),
    "SceneEditor": lambda m, constraints, **o: SceneEditor([m], constraints, **o),
    "make_editor": lambda m, constraints, **o: make_editor([m], constraints, **o),
    "make_editor discrete": lambda m, constraints, **o: make_editor([m], constraints, discrete=True, **o),
}


@pytest.fixture(scope="module")
def foot(walk):
    return goals.foot_goals(walk, foot_contacts(walk))


@pytest.mark.parametrize(("label", "call", "exc", "pattern"), CORE, ids=[c[0] for c in CORE])
def test_a_bad_option_fails_first_naming_itself(label, call, exc, pattern, walk, foot, no_work):
    with pytest.raises(exc, match="Expected " + pattern) as info:
        call(walk, foot)
    assert not isinstance(info.value, WorkStarted)


@pytest.mark.parametrize("entry", list(ENTRIES))
@pytest.mark.parametrize(("options", "exc", "pattern"), EDIT_OPTIONS, ids=[str(o[0]) for o in EDIT_OPTIONS])
def test_a_bad_editing_option_fails_first_through_every_entry(entry, options, exc, pattern, walk, no_work):
    with pytest.raises(exc, match="Expected " + pattern):
        ENTRIES[entry](walk, PIN, **options)


@pytest.mark.parametrize("entry", list(ENTRIES))
def test_constraints_none_is_refused_saying_what_to_give(entry, walk, no_work):
    with pytest.raises(TypeError, match=re.escape("got None: for no constraint give [] (or leave `constraints` out)")):
        ENTRIES[entry](walk, None)
    with pytest.raises(TypeError, match=r"put a single constraint in a list: \[c\]"):
        ENTRIES[entry](walk, PIN[0])


def test_set_constraints_none_is_refused_and_records_nothing(walk):
    ed = SceneEditor([walk], PIN)
    before = ed.snapshot()
    with pytest.raises(TypeError, match="for no constraint give"):
        ed.set_constraints(None)
    assert ed.snapshot() == before and not ed.can_undo
    ed.set_constraints([])  # the spelling of "none"
    assert ed.constraints == ()


def test_the_edge_values_still_edit(walk):
    ed = SceneEditor(
        [walk], PIN, flip_window=0.0, relative_iterations=1, variational_step=1, start_times=np.array([0.0]),
        stationary_speed=0.0,
    )
    assert ed.options["start_times"] == (0.0,) and type(ed.options["variational_step"]) is int
    wide = edit([walk], PIN, flip_window=10 * walk.n_frames / walk.fps, variational_step=3.0).motions[0]
    assert wide.n_frames == walk.n_frames
    assert ml.refine(walk, levels=1, spacing=1e-3, blend=0.0).n_frames == walk.n_frames
    assert ml.refine(walk, levels=goals.MAX_LEVELS, spacing=10.0).n_frames == walk.n_frames


# ------------------------------------------------------------------ staggered
@pytest.fixture(scope="module")
def sm(walk):
    return extract(walk, optimize=False)


def test_extract_takes_the_bounds_of_max_poses(walk):
    assert extract(walk, max_poses=2, optimize=False).n_poses == 2
    every = extract(walk, optimize=False).n_poses
    assert extract(walk, max_poses=walk.n_frames, optimize=False).n_poses == every
    assert extract(walk, max_poses=4.0, optimize=False).n_poses == 4  # a whole float is a count


def test_randomize_bounds_tau_by_the_clip(sm, no_work):
    for bad in (1e308, -1.0, NAN, INF):
        with pytest.raises(ValueError, match=r"Expected `tau` in \[0, [0-9.]+\] seconds \(at most the clip's duration\)"):
            staggered_edit.randomize(sm, bad)


def test_randomize_at_the_clip_duration_still_works(sm):
    out = staggered_edit.randomize(sm, sm.duration, seed=1)
    assert np.all(np.isfinite(out.refinements)) and np.all(np.diff(out.times) > 0)


@pytest.mark.parametrize(
    ("rotation", "pattern"),
    [
        ([NAN, 0.0, 0.0, 1.0], r"`rotations\['LeftLeg'\]` to be a finite quaternion"),
        ([0.0, 0.0, 0.0, 0.0], r"`rotations\['LeftLeg'\]` to be a rotation, a quaternion .* of non-zero length"),
        ([0.0, 0.0, 1.0], r"`rotations\['LeftLeg'\]` to be a quaternion \(x, y, z, w\) of shape \(4,\)"),
    ],
)
def test_edit_pose_refuses_a_nan_or_zero_quaternion(sm, rotation, pattern, no_work):
    with pytest.raises(ValueError, match="Expected " + pattern):
        staggered_edit.edit_pose(sm, 1, rotations={"LeftLeg": rotation})


def test_edit_pose_names_the_joint_of_a_bad_row_and_a_bad_root(sm, no_work):
    q = np.tile([0.0, 0.0, 0.0, 1.0], (sm.n_joints, 1))
    q[3] = 0.0
    with pytest.raises(ValueError, match=r"Expected `rotations\[3\]` \(joint 'LeftLeg'\) to be a rotation"):
        staggered_edit.edit_pose(sm, 1, rotations=q)
    with pytest.raises(ValueError, match=r"Expected `root_position` to be a finite \(x, y, z\) position in metres"):
        staggered_edit.edit_pose(sm, 1, root_position=[NAN, 0.0, 0.0])


def test_edit_pose_normalises_a_quaternion_of_any_length(sm):
    q = np.asarray(sm.rotation_values[1][3])
    once = staggered_edit.edit_pose(sm, 1, rotations={"LeftLeg": q * 0.5})
    twice = staggered_edit.edit_pose(sm, 1, rotations={"LeftLeg": q})
    np.testing.assert_allclose(once.rotation_values, twice.rotation_values, atol=1e-12)


@pytest.fixture
def editor(walk):
    return StaggeredEditor(walk, optimize=False)


@pytest.mark.parametrize(
    ("change", "exc", "pattern"),
    [
        (lambda ed: ed.set_random(NAN), ValueError, r"`tau` in \[0, [0-9.]+\] seconds .*got nan"),
        (lambda ed: ed.set_random(tau=-1), ValueError, r"`tau` .*got -1"),
        (lambda ed: ed.set_random(tau=1e308), ValueError, r"`tau` .*got 1e\+308"),
        (lambda ed: ed.set_random(seed=NAN), ValueError, r"`seed` to be an integer >= 0"),
        (lambda ed: ed.set_pose_count(10**6), ValueError, r"`n` to be an integer in \[2, \d+\] \(the pose count `max_poses`"),
        (lambda ed: ed.set_pose_count(1), ValueError, r"`n` .*max_poses"),
        (lambda ed: ed.set_pose_count(2.5), ValueError, r"`n` .*got 2\.5"),
        (lambda ed: ed.set_pose_count("4"), TypeError, r"`n` to be an integer"),
    ],
)
def test_editor_refuses_a_bad_value_and_records_nothing(editor, change, exc, pattern, monkeypatch):
    before, current = editor.params, editor.current
    monkeypatch.setattr(editor, "_apply", _boom)
    with pytest.raises(exc, match="Expected " + pattern):
        change(editor)
    assert editor.params == before and editor.current is current and not editor.can_undo


def test_editor_takes_the_largest_values_the_clip_holds(editor):
    editor.set_pose_count(editor.n_candidates)
    assert editor.current.n_poses == editor.n_candidates
    editor.set_random(tau=editor.current.duration, seed=2)
    assert editor.tau == editor.current.duration and editor.can_undo
    with pytest.raises(ValueError, match=r"Expected `max_poses` to be an integer in \[2, 120\]"):
        StaggeredEditor(editor.motion, max_poses=NAN, optimize=False)


# ------------------------------------------------------------------ touch-up
def test_touch_up_edge_values_still_run(cmu):
    clip = cmu("16_15").resample(30)[:45]
    history = ml.touch_up(clip, iterations=0, flight_window=0.0, tol=0.0)
    assert history.passes == 0 and np.array_equal(history.motion.rotations, clip.rotations)
    assert ml.touch_up(clip, iterations=1.0, schedule="ground").passes <= 1


# ------------------------------------------------------------------ the one home
def test_checks_messages_and_kinds():
    assert _checks.real(np.float32(0.5), "x", low=0.0) == 0.5 and _checks.integer(np.int64(3), "n") == 3
    with pytest.raises(TypeError, match=r"Expected `x` to be a real number, got bool True"):
        _checks.real(True, "x")
    with pytest.raises(TypeError, match=r"Expected `n` to be an integer >= 0, got NoneType None"):
        _checks.integer(None, "n", low=0)
    with pytest.raises(ValueError, match=r"Expected `x` in \(0, 1\), got 1"):
        _checks.real(1, "x", low=0, high=1, low_open=True, high_open=True)
    with pytest.raises(TypeError, match=r"got str '" + "a" * 76 + r"\.\.\.$"):  # a long value is cut in the message
        _checks.real("a" * 10_000, "x")
    with pytest.raises(ValueError, match=r"Expected `q` to be a finite quaternion"):
        _checks.quaternion([0.0, INF, 0.0, 1.0], "q")


def test_no_option_check_is_written_twice():
    """The entry points ask mocaplab._checks; no hand-written NaN test of these options is left beside it."""
    from pathlib import Path

    root = Path(ml.__file__).parent
    for path, option in [
        ("physics/touchup.py", "iterations"), ("physics/state.py", "flight_window"), ("staggered/fit.py", "max_refinement"),
        ("staggered/edit.py", "tau"), ("editing/scene.py", "variational_step"),
    ]:
        text = (root / path).read_text(encoding="utf-8")
        assert f'raise ValueError(f"Expected `{option}`' not in text, (path, option)


# ------------------------------------------------------------------ widgets: the one error display
class _Unprintable(Exception):
    def __str__(self):
        raise RuntimeError("the message itself fails")


class _Sly(str):
    """A message whose formatting fails: a str subclass with its own __format__."""

    def __format__(self, spec):
        raise RuntimeError("no formatting")


class _SlyMessage(Exception):
    def __str__(self):
        return _Sly("sly <i>message</i>")


def test_error_html_cannot_fail_and_escapes_everything():
    from mocaplab.widgets._controls import MAX_ERROR_TEXT, error_html

    odd = [
        _Unprintable("x"), _SlyMessage(), ValueError("<script>alert(1)</script>"), KeyError(None),
        ValueError("\udcff lone surrogate"), ValueError("x" * 1_000_000),
    ]
    for err in odd:
        for options in ({}, {"trace": True}, {"where": True, "tag": "span", "style": "color:red' onclick='x"}):
            shown = error_html(err, **options)
            assert "mocaplab-error" in shown and type(err).__name__ in shown
            assert "<script" not in shown and "<i>" not in shown and "onclick='x" not in shown
            assert len(shown) < MAX_ERROR_TEXT + 1_000
            shown.encode("utf-8")  # what the page is sent as
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in error_html(odd[2])
    assert "sly &lt;i&gt;message&lt;/i&gt;" in error_html(odd[1])
    left = len("ValueError: ") + 1_000_000 - MAX_ERROR_TEXT  # the type and the message, counted
    assert f"... ({left} more characters not shown)</pre>" in error_html(odd[5])


def _raise(exc):
    raise exc


def test_drag_editor_status_keeps_its_text_through_the_one_display(cmu):
    from mocaplab.widgets.path_editor import PathEditor

    pe = PathEditor([cmu("16_15")[:120]], viewer=False)
    pe._guard(lambda: _raise(ValueError("bad <pin>")))
    status = pe.status.value
    assert status.startswith('<span class=\'mocaplab-error\' style=\'color:#b00020; display:block;')
    assert re.search(r">ValueError: bad &lt;pin&gt; \(_raise, line \d+\)</span>$", status), status
    assert isinstance(pe.last_error, ValueError)
    pe._guard(lambda: _raise(_Unprintable("x")))  # must not raise
    assert "_Unprintable" in pe.status.value and "could not be shown" not in pe.status.value.split(":", 1)[0]


def test_viewer_shows_an_error_whose_message_fails(cmu):
    from mocaplab.widgets.viewer import MotionViewer

    v = MotionViewer(cmu("16_15")[:60], backend="none")
    v.widget  # noqa: B018 - builds the status line
    v._shown(lambda: _raise(_Unprintable("x")))  # a button's action: must not raise
    assert "_Unprintable" in v._status.value and "mocaplab-error" in v._status.value
    v._shown(lambda: _raise(ValueError("<b>" * 100_000)))
    assert "<b>" not in v._status.value and "more characters not shown" in v._status.value
    v.close()
