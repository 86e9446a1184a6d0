"""Checks of the options the public entry points take, before any work is done.

One home for the small checks every paper package needs (Kim's editing and
refinement, Shin's touch-up, Coleman's staggered poses; the ground floor's
goal layer): a real number that must be finite and within a range, a whole
number within a range, a quaternion that can be normalised.  Each returns
the plain Python value it checked and raises with one message shape,
``Expected `name` <what>, got <value>``, so a user sees which option was
wrong and what it takes:

- :class:`TypeError` when the value is not of a usable kind at all (a
  string, None, a bool where a number is asked for);
- :class:`ValueError` when it is of the right kind but not a usable value
  (NaN, infinite, out of range, 2.5 for a count).

A value that would only fail deep inside a solver (``levels=nan`` as
"cannot convert float NaN to integer", ``spacing=0`` as a silent
division) fails here, at the call, naming the option.  This module imports
nothing from mocaplab, so every module may use it.

Examples
--------
>>> real(0.25, "spacing", low=0.0, low_open=True, unit="seconds")
0.25
>>> integer(3.0, "levels", low=1)
3
>>> real(float("nan"), "blend", low=0.0, unit="seconds")
Traceback (most recent call last):
...
ValueError: Expected `blend` >= 0 seconds, got nan
"""

from __future__ import annotations

import math
import numbers
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["real", "integer", "quaternion", "bounds_text"]


def bounds_text(
    low: float | None = None, high: float | None = None, *, low_open: bool = False, high_open: bool = False
) -> str:
    """The range a value must lie in, as the messages say it: ``> 0``, ``<= 1``, ``in (0, 1]``.

    Examples
    --------
    >>> bounds_text(0.0, low_open=True), bounds_text(high=5), bounds_text(0, 1, high_open=True)
    ('> 0', '<= 5', 'in [0, 1)')
    """
    if low is not None and high is not None:
        return f"in {'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"
    if low is not None:
        return f"{'>' if low_open else '>='} {low:g}"
    if high is not None:
        return f"{'<' if high_open else '<='} {high:g}"
    return "finite"


def _shown(value: Any) -> str:
    """``value`` as a message shows it: its repr, cut short when long."""
    try:
        text = repr(value)
    except Exception:  # noqa: BLE001 - a message must not fail on the value it reports
        text = f"<{type(value).__name__} that cannot be shown>"
    return text if len(text) <= 80 else text[:77] + "..."


def _is_real(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def real(
    value: Any,
    name: str,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    high_open: bool = False,
    unit: str = "",
) -> float:
    """A finite real number within ``[low, high]`` (either end open or absent), as a float.

    Parameters
    ----------
    value : object
        What the caller gave.
    name : str
        The option's name, shown between backticks.
    low, high : float, optional
        Bounds (None: unbounded on that side; the value is finite either way).
    low_open, high_open : bool
        Exclude the bound itself.
    unit : str
        Unit said after the range (``"seconds"``).

    Returns
    -------
    float

    Raises
    ------
    TypeError
        ``value`` is not a real number (a string, None, a bool, a complex).
    ValueError
        NaN, infinite or out of range.
    """
    rng = bounds_text(low, high, low_open=low_open, high_open=high_open)
    what = f"{rng} {unit}".rstrip() if rng != "finite" else f"a finite number{' of ' + unit if unit else ''}"
    if not _is_real(value):
        kind = "a real number" + ("" if rng == "finite" else f" {what}")
        raise TypeError(f"Expected `{name}` to be {kind}, got {type(value).__name__} {_shown(value)}")
    v = float(value)
    ok = math.isfinite(v)
    if ok and low is not None:
        ok = v > low if low_open else v >= low
    if ok and high is not None:
        ok = v < high if high_open else v <= high
    if not ok:
        raise ValueError(f"Expected `{name}` {'to be ' if rng == 'finite' else ''}{what}, got {_shown(value)}")
    return v


def integer(value: Any, name: str, *, low: int | None = None, high: int | None = None, why: str = "") -> int:
    """A whole number within ``[low, high]``, as an int (``3.0`` is 3; ``2.5``, NaN and True are refused).

    Parameters
    ----------
    value : object
    name : str
        The option's name.
    low, high : int, optional
        Inclusive bounds.
    why : str
        Said after the range in the message (what the bound stands for).

    Raises
    ------
    TypeError
        Not a number (a string, None, a bool).
    ValueError
        Not whole, not finite or out of range.
    """
    rng = bounds_text(low, high)
    what = "an integer" + ("" if rng == "finite" else f" {rng}") + (f" ({why})" if why else "")
    if not _is_real(value):
        raise TypeError(f"Expected `{name}` to be {what}, got {type(value).__name__} {_shown(value)}")
    v = float(value) if not isinstance(value, (int, np.integer)) else None
    if v is not None and not (math.isfinite(v) and v.is_integer()):
        raise ValueError(f"Expected `{name}` to be {what}, got {_shown(value)}")
    n = int(value)
    if (low is not None and n < low) or (high is not None and n > high):
        raise ValueError(f"Expected `{name}` to be {what}, got {_shown(value)}")
    return n


def quaternion(value: Any, name: str, *, of: str = "") -> NDArray[np.float64]:
    """A finite quaternion ``(x, y, z, w)`` of non-zero length, normalised; shape (4,).

    ``of`` is said after the name (``"(joint 'LeftLeg')"``).

    Examples
    --------
    >>> quaternion([0, 0, 0, 2], "q").tolist()
    [0.0, 0.0, 0.0, 1.0]
    """
    label = f"`{name}` {of}".rstrip()
    try:
        q = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise TypeError(f"Expected {label} to be a quaternion (x, y, z, w), got {_shown(value)}") from None
    if q.shape != (4,):
        raise ValueError(f"Expected {label} to be a quaternion (x, y, z, w) of shape (4,), got shape {q.shape}")
    if not np.all(np.isfinite(q)):
        raise ValueError(f"Expected {label} to be a finite quaternion (x, y, z, w), got {_shown(q.tolist())}")
    n = float(np.linalg.norm(q))
    if n < 1e-12:
        raise ValueError(
            f"Expected {label} to be a rotation, a quaternion (x, y, z, w) of non-zero length (the identity is "
            f"(0, 0, 0, 1)), got {_shown(q.tolist())}"
        )
    out: NDArray[np.float64] = q / n
    return out
