"""Old spellings of the public API, each answered with what to write instead.

When a name or a keyword changes (one convention per concept: half-open
intervals, ``contacts="auto"``, windows in seconds, a result's ``.motion``),
the old spelling is not kept as a second name for the same thing; it fails
at once with an error that spells the new call.  Two tools:

- :class:`Gone`, a class attribute that raises ``AttributeError`` when read
  on an instance, naming the replacement;
- :func:`reject_keywords`, for a function's ``**removed`` keywords: a
  ``TypeError`` naming the replacement of each known old keyword, or
  listing the allowed ones.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any, NoReturn, overload

__all__ = ["Gone", "reject_keywords"]


class Gone:
    """A removed attribute or method: reading it on an instance raises ``AttributeError`` with ``instead``.

    Parameters
    ----------
    instead : str
        What to write instead, e.g. ``"write mocaplab.staggered.succession(sm, ...)"``.

    Examples
    --------
    >>> class Result:
    ...     final = Gone("read .motion")
    >>> Result().final
    Traceback (most recent call last):
    ...
    AttributeError: Result.final is gone: read .motion
    """

    def __init__(self, instead: str) -> None:
        self.instead = instead
        self.name = ""

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    @overload
    def __get__(self, obj: None, owner: type | None = None) -> Gone: ...
    @overload
    def __get__(self, obj: object, owner: type | None = None) -> NoReturn: ...
    def __get__(self, obj: object | None, owner: type | None = None) -> Gone:
        if obj is None:
            return self
        raise AttributeError(f"{type(obj).__name__}.{self.name} is gone: {self.instead}")


def reject_keywords(function: str, given: Mapping[str, Any], renamed: Mapping[str, str], allowed: Iterable[str]) -> None:
    """Raise ``TypeError`` for keywords a function no longer takes (nothing when ``given`` is empty).

    Parameters
    ----------
    function : str
        The function's name, for the message.
    given : mapping
        The keywords left over (a ``**removed`` catch-all).
    renamed : mapping of str to str
        For each old keyword, what to write instead.
    allowed : iterable of str
        The keywords the function takes, listed for an unknown one.

    Examples
    --------
    >>> reject_keywords("refine", {"feet": False}, {"feet": "contacts=None plants no feet"}, ["contacts"])
    Traceback (most recent call last):
    ...
    TypeError: refine() no longer takes `feet`: contacts=None plants no feet
    """
    for name in given:
        if name in renamed:
            raise TypeError(f"{function}() no longer takes `{name}`: {renamed[name]}")
    if given:
        raise TypeError(f"{function}() got unexpected keywords {sorted(given)}; allowed: {sorted(allowed)}")
