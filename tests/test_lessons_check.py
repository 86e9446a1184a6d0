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


@pytest.mark.parametrize("bad", [float("inf"), float("nan"), [1.0, float("nan")], np.array([np.inf])])
def test_a_non_finite_expected_is_a_lesson_bug(bad: object) -> None:
    with pytest.raises(ValueError, match="a bug in the lesson"):
        check(1.0 if np.ndim(bad) == 0 else [1.0] * np.size(bad), bad)


def test_a_ragged_expected_is_a_lesson_bug_and_a_ragged_answer_a_wrong_shape() -> None:
    with pytest.raises(ValueError, match="ragged"):
        check([[1, 2], [3]], [[1, 2], [3]])
    with pytest.raises(CheckError, match=r"expected shape \(2, 2\)"):
        check([[1, 2], [3]], [[1, 2], [3, 4]])
    assert check([[1, 2], [3, 4]], [[1, 2], [3, 4]], quiet=True)


def test_boolean_arrays_need_booleans_or_exactly_0_and_1() -> None:
    expected = np.array([True, False])
    for wrong in ([0.3, 0.0], [5, 0], ["yes", ""]):
        with pytest.raises(CheckError, match="True or False entries"):
            check(wrong, expected)
    assert check([1, 0], expected, quiet=True) and check(np.array([True, False]), [True, False], quiet=True)
    with pytest.raises(CheckError, match="1 of 2 entries are off"):
        check([1, 1], expected)


def test_strings_compare_entry_by_entry_whatever_the_container() -> None:
    assert check(("a", "b"), ["a", "b"], quiet=True)
    assert check(np.array(["a", "b"]), np.array(["a", "b"]), quiet=True)
    assert check(["a", "b"], np.array(["a", "b"]), quiet=True)
    with pytest.raises(CheckError, match="1 of 2 entries are off") as e:
        check(("a", "c"), ["a", "secret"])
    assert "secret" not in str(e.value)
    with pytest.raises(CheckError, match="not yet"):
        check(["a", 1], ["a", "1"])  # a number is not the string of its digits
    with pytest.raises(CheckError, match=r"expected shape \(2,\)"):
        check("ab", ["a", "b"])


def test_huge_integers_are_compared_exactly() -> None:
    assert check(10**400, 10**400, quiet=True)
    with pytest.raises(CheckError, match="too high"):
        check(10**400 + 10**399, 10**400)
    with pytest.raises(CheckError, match="too high"):
        check(10**400, 1.0)
    with pytest.raises(CheckError, match="too low"):
        check(1.0, 10**400)
    assert check([10**400], [10**400], quiet=True)


def test_a_0d_array_is_a_number_and_the_kind_still_matters() -> None:
    assert check(np.array(0.5), 0.5, quiet=True)
    assert check(0.5, np.array(0.5), quiet=True)
    assert check(np.array(True), True, quiet=True)
    with pytest.raises(CheckError, match="too low"):
        check(np.array(0.25), 0.5)
    with pytest.raises(CheckError, match="expected a number, got list"):
        check([0.5], 0.5)
    with pytest.raises(CheckError, match="not yet"):
        check(np.array(["a"]), "a")  # an array is not the string it holds


def test_feedback_never_shows_the_expected_value() -> None:
    secret = 1234.5678
    for answer in (1.0, 1e9, [1.0], "x", True, np.array([1.0, 2.0])):
        with pytest.raises(CheckError) as e:
            check(answer, secret)
        assert "1234" not in str(e.value)
    with pytest.raises(CheckError) as e:
        check([1.0, 2.0], [secret, 2.0])
    assert "1234" not in str(e.value)
    with pytest.raises(ValueError, match="non-negative"):
        check(1.0, 1.0, atol=float("inf"))
