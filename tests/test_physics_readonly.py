"""Every array the physics records expose or cache is read-only for good (issue 17).

``arr.flags.writeable = False`` on an array that owns its memory can be
undone by anyone with ``arr.flags.writeable = True``; the records hand out
views of read-only owners (:func:`mocaplab.motion.readonly`), for which
numpy refuses.  States of a touch-up history share their Balance objects
and kinematics with the next step, and bodies and link sets are cached, so
an array written through would corrupt other records silently.
"""

from __future__ import annotations

import dataclasses
import inspect

import numpy as np
import pytest

from mocaplab._api import Gone
from mocaplab.physics import (
    GROUND_SCHEDULE,
    Balance,
    Body,
    MassFit,
    TouchUpHistory,
    TouchUpSession,
    TouchUpState,
    balance,
    fit_masses,
    link_sets,
    touch_up,
)
from mocaplab.physics.schedule import LinkSets

#: The physics records whose arrays are checked (other objects they hold,
#: motions and contacts, are frozen by their own modules).
RECORDS = (Balance, Body, TouchUpState, TouchUpHistory, MassFit, LinkSets)


def _arrays(obj, path="", seen=None):
    """(path, array) for every array reachable from a record: attributes, properties, caches, containers."""
    seen = set() if seen is None else seen
    if isinstance(obj, np.ndarray):
        yield path, obj
        return
    if id(obj) in seen:  # records and containers once (arrays under every name)
        return
    seen.add(id(obj))
    if type(obj) in (tuple, list):
        for k, v in enumerate(obj):
            yield from _arrays(v, f"{path}[{k}]", seen)
    elif type(obj) is dict:  # caches (not scipy's OptimizeResult, a dict of the optimiser's own)
        for k, v in obj.items():
            yield from _arrays(v, f"{path}[{k!r}]", seen)
    elif isinstance(obj, RECORDS):
        names = {n for n in dir(obj) if not n.startswith("__")} | set(vars(obj))
        for name in sorted(names):
            if isinstance(inspect.getattr_static(obj, name, None), Gone):
                continue  # a retired name: reading it says what to read instead
            value = getattr(obj, name)
            if callable(value) and not isinstance(value, np.ndarray):
                continue
            yield from _arrays(value, f"{path}.{name}", seen)


def _assert_frozen(record, expect: tuple[str, ...]):
    found = dict(_arrays(record, type(record).__name__))
    for name in expect:
        assert any(p.endswith(name) or f"{name}[" in p for p in found), f"{name} not reached: {sorted(found)}"
    for path, arr in found.items():
        assert not arr.flags.writeable, path
        with pytest.raises(ValueError):
            arr.flags.writeable = True
    return found


def test_the_check_can_fail():
    """An array made read-only by its flag alone can be switched back: the check catches it."""
    arr = np.zeros((1, 3))
    arr.flags.writeable = False
    body = Body(("a",), ("rod",), [0], [[0.0, 1.0, 0.0]], [1.0])
    _assert_frozen(body, ("offsets",))
    leak = dataclasses.replace(body)
    object.__setattr__(leak, "offsets", arr)  # what Body did before issue 17
    with pytest.raises(pytest.fail.Exception, match="DID NOT RAISE"):
        _assert_frozen(leak, ())


@pytest.fixture(scope="module")
def walk30(cmu):
    return cmu("16_15").resample(30.0)


def test_body_arrays_and_caches(walk30):
    body = Body.from_skeleton(walk30)
    _, column = body.support_points(walk30, ["LeftFoot", "LeftToeBase"])
    balance(walk30, body)  # fills the body's layout caches
    found = _assert_frozen(body, ("owners", "offsets", "masses", "point_owners", "point_offsets", "_layout_cache", "_point_layout_cache"))
    assert len(found) >= 5 + 3 + 2
    with pytest.raises(ValueError):
        column.flags.writeable = True  # the cached layout handed out


def test_balance_arrays_and_caches(walk30):
    bal = balance(walk30)
    bal.signed_distance  # noqa: B018 (a cached property)
    names = ("zmp", "projection", "distance", "com", "ground", "support", "active", "positions", "accelerations")
    _assert_frozen(bal, names + ("signed_distance", "_raw", "_segments"))
    # a Balance built from outside arrays copies them: the caller's arrays stay theirs
    mine = {f.name: np.array(getattr(bal, f.name)) for f in dataclasses.fields(bal)}
    other = Balance(**mine)
    assert mine["zmp"].flags.writeable and not other.zmp.flags.writeable
    mine["zmp"][:] = 0.0
    assert not np.array_equal(other.zmp, mine["zmp"], equal_nan=True)


def test_touch_up_states_and_history(walk30):
    hist = touch_up(walk30, iterations=1, tol=None)
    for state in hist.states:
        state.violation  # noqa: B018 (a cached property)
        _assert_frozen(state, ("kinematics[0]", "kinematics[1]", "violation", "zmp_distance", "balance.zmp", "body.offsets"))
    _assert_frozen(hist, ("zmp_distance", "mean_zmp_distance", "errors", "dropped"))
    session = TouchUpSession(walk30)
    session.forward()
    _assert_frozen(session.history, ("errors",))
    _assert_frozen(session.current, ("kinematics[0]", "balance.signed_distance"))


def test_link_sets_and_mass_fit(walk30):
    sets = link_sets(walk30.skeleton, GROUND_SCHEDULE[0])
    _assert_frozen(sets, ("roles", "part", "carried_top"))
    fit = fit_masses(walk30, max_iterations=3)
    _assert_frozen(fit, ("body.masses", "initial.masses"))
