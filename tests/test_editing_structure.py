"""The shape of mocaplab.editing: no import cycles, no module state, immutable results, one discrete editor."""

from __future__ import annotations

import importlib
import sys
import types

import numpy as np
import pytest
from test_structure import GRAPH, MODS  # the one import graph of the package (every import counts)

from mocaplab.editing import DiscreteEditor, PinPosition, SceneEditor, edit, make_editor

MODULES = sorted(m for m in GRAPH if m == "mocaplab.editing" or m.startswith("mocaplab.editing."))
CONTINUOUS = (
    "mocaplab.editing.scene", "mocaplab.editing.laplacian", "mocaplab.editing.spatial", "mocaplab.editing.lsq",
    "mocaplab.editing.flips", "mocaplab.editing.timewarp", "mocaplab.editing.graph", "mocaplab.editing.refinement",
)


def test_there_are_the_modules():
    assert "mocaplab.editing.discrete.editor" in MODULES and "mocaplab.editing.scene" in MODULES
    assert "mocaplab.editing.discrete" in MODULES and all(not m.endswith("__init__") for m in MODULES)


def test_the_continuous_modules_never_import_the_discrete_package():
    # the discrete package wraps the continuous editor, not the other way round (cycles: tests/test_structure.py)
    for m in CONTINUOUS:
        assert not {d for d in GRAPH[m] if d.startswith("mocaplab.editing.discrete")}, m


@pytest.mark.parametrize("name", MODULES)
def test_each_module_imports_alone(name):
    saved = {k: v for k, v in sys.modules.items() if k == "mocaplab.editing" or k.startswith("mocaplab.editing.")}
    try:
        for k in saved:
            del sys.modules[k]
        importlib.import_module(name)
    finally:
        for k in [k for k in sys.modules if k == "mocaplab.editing" or k.startswith("mocaplab.editing.")]:
            del sys.modules[k]
        sys.modules.update(saved)
        # a re-import rebinds each submodule on its parent package: point them back at the saved modules
        for k, mod in saved.items():
            parent, _, child = k.rpartition(".")
            if parent in sys.modules:
                setattr(sys.modules[parent], child, mod)


@pytest.mark.parametrize("name", MODULES)
def test_no_module_level_mutable_state(name):
    mod = importlib.import_module(name)
    bad = []
    for key, value in vars(mod).items():
        if key.startswith("__") or isinstance(value, types.ModuleType):
            continue
        if isinstance(value, (dict, list, set, bytearray)) or type(value).__name__.startswith("Weak"):
            bad.append(key)
        elif isinstance(value, np.ndarray) and value.flags.writeable:
            bad.append(key)
    assert not bad, f"{name}: module-level mutable objects {bad}"


def test_no_class_name_checks():
    for path in (MODS[m] for m in MODULES):
        src = path.read_text()
        assert "__name__ ==" not in src and '__name__ !=' not in src, path


@pytest.fixture(scope="module")
def walk(mocap_dir):
    from mocaplab import data

    return data.cmu("16_15").resample(30)


def pins(walk, factor):
    P = walk.root_positions[:, [0, 2]]
    return [PinPosition(0, 0, P[0], hard=True), PinPosition(0, walk.n_frames - 1, P[0] + factor * (P[-1] - P[0]), hard=True)]


def test_results_are_immutable(walk):
    res = edit([walk], pins(walk, 1.2))
    with pytest.raises(AttributeError, match="immutable"):
        res.transformations = ("x",)
    with pytest.raises(AttributeError, match="immutable"):
        res.paths = ()
    other = res.with_transformations(("t",))
    assert other.transformations == ("t",) and res.transformations == ()
    assert other.paths is res.paths  # the edit itself is shared
    with pytest.raises(ValueError):
        res.paths[0][0, 0] = 1.0  # read-only arrays


def test_the_discrete_editor_wraps_a_continuous_one(walk):
    ed = make_editor([walk], pins(walk, 1.0), discrete=True)
    assert isinstance(ed, DiscreteEditor) and isinstance(ed.scene, SceneEditor)
    assert isinstance(make_editor([walk], pins(walk, 1.0)), SceneEditor)
    before = ed.result
    res = ed.drag(1, pins(walk, 1.5)[1].position)
    assert res.transformations and before.transformations == ()  # the earlier result is untouched
    assert res is ed.result and res.characters == ed.scene.characters
    assert ed.scene.result.transformations == ()  # the continuous editor's own result: no discrete record
    # the continuous editor agrees with a fresh continuous edit of the transformed clips
    fresh = edit(list(ed.scene.characters), ed.scene.constraints)
    np.testing.assert_allclose(res.paths[0], fresh.paths[0], atol=1e-9)
    # and edit(..., discrete=True) is DiscreteEditor(...).result with the greedy steps of a first solve
    one = edit([walk], pins(walk, 1.5), discrete=True)
    assert [str(t) for t in one.transformations] == [str(t) for t in DiscreteEditor([walk], pins(walk, 1.5)).result.transformations]


def test_a_failed_discrete_update_leaves_the_editor_unchanged(walk):
    from mocaplab.editing import ConstraintError

    ed = DiscreteEditor([walk], pins(walk, 1.0))
    ed.drag(1, pins(walk, 1.5)[1].position)
    before = (ed.result, ed.constraints, ed.tracks, ed.applied, ed.history, ed.scene.result)
    P = walk.root_positions[:, [0, 2]]
    with pytest.raises(ConstraintError):
        ed.add(PinPosition(0, 0, P[0] + 0.5, hard=True))  # disagrees with the hard pin on frame 0
    assert (ed.result, ed.constraints, ed.tracks, ed.applied, ed.history, ed.scene.result) == before
    again = ed.drag(1, pins(walk, 1.6)[1].position)
    assert again.hard_residual_space < 1e-6
