"""Instant feedback for the lessons' exercises, without giving the answer away.

The lessons end with predict-then-check exercises written in nbgrader's
format: the student's answer goes between ``### BEGIN SOLUTION`` and
``### END SOLUTION`` (removed in the student version), and a graded cell
checks it.  :func:`check` is what such a cell calls: it compares the answer
with a value the lesson computed independently and says *how* the answer is
off (too high, too low, wrong shape, how many entries) but never prints the
expected value, so a student can try again.

Example
-------
>>> check(0.52, 0.5, name="stride (m)", rtol=0.1)
ok: stride (m)
True
>>> try:
...     check(0.9, 0.5, name="stride (m)", rtol=0.1)
... except CheckError as e:
...     print(e)
stride (m): not yet, your answer is too high
"""

from __future__ import annotations

import math
import numbers
from fractions import Fraction
from typing import Any

import numpy as np

__all__ = ["CheckError", "check"]


class CheckError(AssertionError):
    """An exercise answer that does not match (an AssertionError, so nbgrader counts it as failed)."""


def check(
    answer: Any,
    expected: Any,
    *,
    name: str = "answer",
    rtol: float = 1e-2,
    atol: float = 0.0,
    hint: str | None = None,
    quiet: bool = False,
) -> bool:
    """Check an exercise answer against the lesson's own result.

    Parameters
    ----------
    answer : number, bool, str, sequence or ndarray
        The student's value.  ``...`` or None (the placeholder left in a
        student version) is reported as "no answer yet".
    expected : same kind as ``answer``
        The value the lesson computed.  Numbers and arrays match within
        ``atol + rtol * |expected|`` (elementwise); booleans, strings and
        other values must be equal.
    name : str
        What the answer is, shown in the feedback.
    rtol, atol : float
        Tolerances for numbers (default 1 %).
    hint : str, optional
        Appended to the feedback when the answer is off.
    quiet : bool
        Do not print the "ok" line.

    Returns
    -------
    True when the answer matches.

    Raises
    ------
    CheckError
        When it does not, saying how (never showing ``expected``).
    """
    if not (0 <= rtol < math.inf and 0 <= atol < math.inf):
        raise ValueError(f"Expected finite non-negative `rtol` and `atol`, got {rtol!r} and {atol!r}")
    problem = _problem(answer, expected, rtol=rtol, atol=atol)
    if problem is not None:
        raise CheckError(f"{name}: {problem}" + (f" ({hint})" if hint else ""))
    if not quiet:
        print(f"ok: {name}")
    return True


def _is_number(x: Any) -> bool:
    return isinstance(x, numbers.Real | np.floating | np.integer) and not isinstance(x, bool | np.bool_)


def _exact(x: Any) -> Fraction:
    """A real number as an exact fraction: no overflow for huge integers, no rounding for floats."""
    return Fraction(int(x)) if isinstance(x, numbers.Integral) else Fraction(float(x))


def _finite(x: Any) -> bool:
    return isinstance(x, numbers.Integral) or math.isfinite(float(x))


def _bad_expected(what: str) -> ValueError:
    # a bug in the lesson, not in the student's answer: say so, still without the value
    return ValueError(f"Expected {what} for `expected` (a bug in the lesson, not in your answer)")


def _equal(a: Any, e: Any) -> bool:
    try:
        same = a == e
        return bool(same) if isinstance(same, bool | np.bool_) else False
    except Exception:  # noqa: BLE001 (any comparison that cannot be made is "not equal")
        return False


def _problem(answer: Any, expected: Any, *, rtol: float, atol: float) -> str | None:
    if answer is None or answer is Ellipsis:
        return "no answer yet: replace the placeholder with your prediction"
    if isinstance(expected, np.ndarray) and expected.ndim == 0:
        expected = expected.item()
    if isinstance(answer, np.ndarray) and answer.ndim == 0:
        answer = answer.item()  # a 0-d array is a number (or a bool, or a string)
    if isinstance(expected, bool | np.bool_):
        if not isinstance(answer, bool | np.bool_):
            return f"expected True or False, got {type(answer).__name__}"
        return None if bool(answer) == bool(expected) else "not yet"
    if _is_number(expected):
        if not _finite(expected):
            raise _bad_expected("a finite number")
        if not _is_number(answer):
            return f"expected a number, got {type(answer).__name__}"
        if not _finite(answer):
            return "expected a finite number, got " + str(float(answer))
        a, e = _exact(answer), _exact(expected)
        if abs(a - e) <= _exact(atol) + _exact(rtol) * abs(e):
            return None
        return "not yet, your answer is too " + ("high" if a > e else "low")
    if isinstance(expected, np.ndarray | list | tuple):
        return _array_problem(answer, expected, rtol=rtol, atol=atol)
    return None if _equal(answer, expected) else "not yet"


def _array_problem(answer: Any, expected: Any, *, rtol: float, atol: float) -> str | None:
    try:
        e_arr = np.asarray(expected)
    except (ValueError, TypeError) as exc:
        raise _bad_expected("a regular array or nested list (not ragged)") from exc
    numeric = e_arr.dtype.kind in "biuf"
    try:
        a_arr = np.asarray(answer) if numeric else np.asarray(answer, dtype=object)
    except (ValueError, TypeError):
        return f"expected shape {e_arr.shape}, got a ragged {type(answer).__name__}"
    if a_arr.shape != e_arr.shape:
        return f"expected shape {e_arr.shape}, got {a_arr.shape}"
    if e_arr.dtype.kind == "b":
        if a_arr.dtype.kind != "b" and not (a_arr.dtype.kind in "iuf" and np.isin(a_arr, (0, 1)).all()):
            return f"expected True or False entries of shape {e_arr.shape}, got {a_arr.dtype} entries"
        off = a_arr.astype(bool) != e_arr
    elif numeric:
        ef = e_arr.astype(float)
        if not np.isfinite(ef).all():
            raise _bad_expected("finite numbers")
        if a_arr.dtype.kind not in "biuf":
            return f"expected numbers of shape {e_arr.shape}, got {a_arr.dtype} entries"
        off = ~(np.abs(a_arr.astype(float) - ef) <= atol + rtol * np.abs(ef))
    else:
        # strings, huge integers, mixed entries: each entry compared as a scalar answer
        off = np.array(
            [_problem(a, e, rtol=rtol, atol=atol) is not None for a, e in zip(a_arr.flat, e_arr.flat, strict=True)],
            dtype=bool,
        )
    n = int(np.count_nonzero(off))
    return None if n == 0 else f"not yet, {n} of {off.size} entries are off"
