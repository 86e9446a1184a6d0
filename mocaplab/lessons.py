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

import numbers
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
    if not (rtol >= 0 and atol >= 0):
        raise ValueError(f"Expected non-negative `rtol` and `atol`, got {rtol!r} and {atol!r}")
    problem = _problem(answer, expected, rtol=rtol, atol=atol)
    if problem is not None:
        raise CheckError(f"{name}: {problem}" + (f" ({hint})" if hint else ""))
    if not quiet:
        print(f"ok: {name}")
    return True


def _is_number(x: Any) -> bool:
    return isinstance(x, numbers.Real) and not isinstance(x, bool) or isinstance(x, np.floating | np.integer)


def _problem(answer: Any, expected: Any, *, rtol: float, atol: float) -> str | None:
    if answer is None or answer is Ellipsis:
        return "no answer yet: replace the placeholder with your prediction"
    if isinstance(expected, bool | np.bool_):
        if not isinstance(answer, bool | np.bool_):
            return f"expected True or False, got {type(answer).__name__}"
        return None if bool(answer) == bool(expected) else "not yet"
    if _is_number(expected):
        if not _is_number(answer):
            return f"expected a number, got {type(answer).__name__}"
        a, e = float(answer), float(expected)
        if not np.isfinite(a):
            return f"expected a finite number, got {a}"
        if abs(a - e) <= atol + rtol * abs(e):
            return None
        return "not yet, your answer is too " + ("high" if a > e else "low")
    if isinstance(expected, np.ndarray | list | tuple) and not isinstance(expected, str):
        e_arr = np.asarray(expected)
        if e_arr.dtype.kind in "biuf":
            try:
                a_arr = np.asarray(answer, dtype=float)
            except (TypeError, ValueError):
                return f"expected numbers of shape {e_arr.shape}, got {type(answer).__name__}"
            if a_arr.shape != e_arr.shape:
                return f"expected shape {e_arr.shape}, got {a_arr.shape}"
            if e_arr.dtype.kind == "b":
                off = a_arr.astype(bool) != e_arr
            else:
                ef = e_arr.astype(float)
                off = ~(np.abs(a_arr - ef) <= atol + rtol * np.abs(ef))
            n = int(np.count_nonzero(off))
            return None if n == 0 else f"not yet, {n} of {off.size} entries are off"
    return None if answer == expected else "not yet"
