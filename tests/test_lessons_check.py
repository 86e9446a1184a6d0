"""mocaplab.lessons.check: feedback that says how an answer is off, never what the answer is."""

from __future__ import annotations

import numpy as np
import pytest

from mocaplab.lessons import CheckError, check


def test_numbers_within_tolerance_pass_and_others_say_high_or_low(capsys: pytest.CaptureFixture[str]) -> None:
    assert check(1.004, 1.0, name="x") is True
    assert "ok: x" in capsys.readouterr().out
    with pytest.raises(CheckError, match="x: not yet, your answer is too high") as e:
        check(1.5, 1.2345678, name="x")
    assert "1.23" not in str(e.value)
    with pytest.raises(CheckError, match="too low"):
        check(0.5, 1.0)
    assert check(0.0, 1e-9, atol=1e-6, quiet=True)
    assert isinstance(CheckError("m"), AssertionError)  # nbgrader counts it as a failed test


@pytest.mark.parametrize("placeholder", [None, ...])
def test_placeholders_are_no_answer_yet(placeholder: object) -> None:
    with pytest.raises(CheckError, match="no answer yet"):
        check(placeholder, 3.0)


def test_kinds_must_match() -> None:
    with pytest.raises(CheckError, match="expected a number, got str"):
        check("3", 3.0)
    with pytest.raises(CheckError, match="expected True or False"):
        check(1, True)
    assert check(np.True_, True, quiet=True)
    with pytest.raises(CheckError, match="expected a finite number"):
        check(float("nan"), 1.0)
    assert check("left", "left", quiet=True)
    with pytest.raises(CheckError, match="not yet"):
        check("right", "left")


def test_arrays_report_shape_and_count_only() -> None:
    e = np.array([1.0, 2.0, 3.0])
    assert check([1.0, 2.0, 3.001], e, quiet=True)
    with pytest.raises(CheckError, match=r"expected shape \(3,\), got \(2,\)"):
        check([1.0, 2.0], e)
    with pytest.raises(CheckError, match="1 of 3 entries are off"):
        check([1.0, 2.5, 3.0], e)
    with pytest.raises(CheckError, match="2 of 3 entries are off"):
        check([True, True, True], np.array([True, False, False]))
    with pytest.raises(ValueError, match="non-negative"):
        check(1.0, 1.0, rtol=-1)
