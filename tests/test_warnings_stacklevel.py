"""Warnings point at the user's line, not at a line inside mocaplab or functools (issue 22, item 8).

Every warning of the package goes through :func:`mocaplab._warnings.warn`,
which attributes it to the first frame outside the package (and outside
``functools``/``contextlib``, which cached properties and context managers
add).  Each test records the warnings of one call made on a line of this
file and checks that they name this file and that line.
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
import sys
import types
import warnings
from pathlib import Path

import numpy as np
import pytest

import mocaplab
from mocaplab import load, quat
from mocaplab._warnings import user_stacklevel, warn
from mocaplab.io import load_bvh, save_bvh
from mocaplab.motion import Motion, Skeleton

DATA = Path(__file__).parent / "data"
PACKAGE = Path(mocaplab.__file__).parent


def lineno() -> int:
    """The line of the caller."""
    return inspect.currentframe().f_back.f_lineno  # type: ignore[union-attr]


def places(caught: list[warnings.WarningMessage]) -> list[tuple[str, int]]:
    return [(w.filename, w.lineno) for w in caught]


def test_unit_guess_in_load_points_at_the_callers_line():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        line = lineno() + 1
        load(DATA / "chain3.bvh")
    assert [str(w.message).split(": ", 1)[1][:18] for w in caught] == ["BVH has no unit; a"]
    assert places(caught) == [(__file__, line)]


def test_unit_guess_in_load_bvh_points_at_the_callers_line():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        line = lineno() + 1
        load_bvh(DATA / "chain3.bvh")
    assert places(caught) == [(__file__, line)]


def test_up_axis_warning_points_at_the_callers_line(cmu, tmp_path):
    walk = cmu("16_15")[:20]
    turned = walk.transformed(rotation=np.array([np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)]))  # Y up -> Z up
    save_bvh(turned, tmp_path / "z.bvh", scale=0.01)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        line = lineno() + 1
        load(tmp_path / "z.bvh", scale=0.01)
    assert ["stands along +Z" in str(w.message) for w in caught] == [True]
    assert places(caught) == [(__file__, line)]


def test_encoding_warning_points_at_the_callers_line(tmp_path):
    path = tmp_path / "latin1.bvh"
    path.write_bytes((DATA / "chain3.bvh").read_bytes().replace(b"JOINT mid", b"JOINT H\xfcfte"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        line = lineno() + 1
        load(path, scale=0.01)
    assert ["is not UTF-8" in str(w.message) for w in caught] == [True]
    assert places(caught) == [(__file__, line)]


def test_roles_warning_through_a_cached_property_points_at_the_callers_line(cmu):
    """``skeleton.roles`` is a functools.cached_property: the warning once pointed at functools.py."""
    sk = cmu("16_15").skeleton
    plain = dataclasses.replace(sk, names=tuple(f"j{i:02d}" for i in range(sk.n_joints)))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        line = lineno() + 1
        plain.roles  # noqa: B018
    assert caught and all("geometry" in str(w.message) for w in caught)
    assert set(places(caught)) == {(__file__, line)}


def test_path_joint_warning_through_a_cached_property_points_at_the_callers_line():
    sk = Skeleton(["ref", "pelvis", "tip"], [-1, 0, 1], [[0, 0, 0], [0, 1, 0], [0, 1, 0]])
    translations = np.zeros((3, 3, 3))
    translations[:] = sk.offsets
    translations[:, 1, 0] = [0.0, 0.5, 1.0]  # the pelvis travels below a static joint 0
    m = Motion(sk, quat.identity((3, 3)), np.zeros((3, 3)), 30.0, translations=translations)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        line = lineno() + 1
        m.path_joint  # noqa: B018
    assert ["follows joint 'pelvis'" in str(w.message) for w in caught] == [True]
    assert places(caught) == [(__file__, line)]


def test_the_first_frame_outside_the_package_is_the_users():
    """A user function between two package frames: the warning points into the user's function."""
    inner = types.ModuleType("mocaplab._fake_inner")
    exec("from mocaplab._warnings import warn\ndef deep():\n    warn('deep', UserWarning)\n", inner.__dict__)
    outer = types.ModuleType("mocaplab._fake_outer")
    exec("def through(f):\n    return f()\n", outer.__dict__)

    def users_callback():
        return inner.deep()  # the user's line: the first frame outside mocaplab

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        outer.through(users_callback)
    assert places(caught) == [(__file__, users_callback.__code__.co_firstlineno + 1)]


def test_stacklevel_counts_package_frames_only():
    def direct() -> int:
        return user_stacklevel()

    assert direct() == 1  # called from a frame outside the package: that frame
    fake = types.ModuleType("mocaplab._fake")
    exec("from mocaplab._warnings import user_stacklevel\ndef f():\n    return user_stacklevel()\n", fake.__dict__)
    assert fake.f() == 2  # the package frame, then this test's
    functools_like = types.ModuleType("functools")
    exec("def g(h):\n    return h()\n", functools_like.__dict__)
    assert functools_like.g(fake.f) == 3  # and a functools frame is skipped too


def test_warn_takes_a_category():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        warn("x", RuntimeWarning)
    assert [w.category for w in caught] == [RuntimeWarning]


# Warnings that keep their own stacklevel on purpose, with the reason.
OWN_STACKLEVEL = {
    # shown once per trial and process by Python's default filter: the warning's place is its own line
    "data.py": "_warn_unverified",
    # a stack-walking copy of this helper written in parallel with it; it should call mocaplab._warnings.warn
    "ik.py": "_warn",
}


def test_every_package_warning_goes_through_the_helper():
    """No ``warnings.warn`` call in mocaplab/ outside the helper (except the listed, deliberate ones)."""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.name == "_warnings.py":
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef):
                for call in ast.walk(node):
                    if (
                        isinstance(call, ast.Call)
                        and isinstance(call.func, ast.Attribute)
                        and call.func.attr == "warn"
                        and isinstance(call.func.value, ast.Name)
                        and call.func.value.id == "warnings"
                        and OWN_STACKLEVEL.get(path.name) != node.name
                    ):
                        found.append(f"{path.relative_to(PACKAGE)}:{call.lineno} in {node.name}")
    assert found == [], "use mocaplab._warnings.warn: " + ", ".join(sorted(set(found)))


@pytest.mark.skipif(sys.version_info < (3, 10), reason="match statement era")
def test_helper_is_importable_without_side_effects():
    before = warnings.filters[:]
    import mocaplab._warnings  # noqa: F401

    assert warnings.filters == before
