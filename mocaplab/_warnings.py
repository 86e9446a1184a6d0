"""One way to warn: at the user's line, not at a line inside mocaplab.

A warning raised deep inside the package (a unit guessed while reading a
file, a correction made while inferring joint roles under a cached property)
is only useful if it points at the line the user wrote.  A fixed
``stacklevel`` cannot do that: the same function is reached through
different depths of package code, and through ``functools.cached_property``
or ``contextlib`` wrappers.  :func:`warn` walks the stack instead and
attributes the warning to the first frame outside the package (and outside
those standard-library wrappers).

Every warning of the package goes through :func:`warn`.
"""

from __future__ import annotations

import sys
import warnings

__all__ = ["warn", "user_stacklevel"]

#: Modules whose frames are never the user's line: the package itself (any
#: ``mocaplab.*`` module, the widgets included) and the standard-library
#: wrappers that package code is reached through.
_INTERNAL_PACKAGES = ("mocaplab",)
_INTERNAL_MODULES = frozenset(("functools", "contextlib"))


def _internal(module: object) -> bool:
    if not isinstance(module, str):
        return False
    if module in _INTERNAL_MODULES:
        return True
    return any(module == p or module.startswith(p + ".") for p in _INTERNAL_PACKAGES)


def user_stacklevel() -> int:
    """The ``stacklevel`` at which the caller's :func:`warnings.warn` points at the first frame outside mocaplab.

    Returns
    -------
    int
        1 is the caller's own frame; each frame of a ``mocaplab`` module (or
        of ``functools``/``contextlib``) above it adds one.  When every frame
        is internal (code run by the package itself), the outermost frame.
    """
    frame = sys._getframe(1)  # the frame that calls warnings.warn
    level = 1
    while frame.f_back is not None and _internal(frame.f_globals.get("__name__")):
        frame = frame.f_back
        level += 1
    return level


def warn(message: str | Warning, category: type[Warning] = UserWarning) -> None:
    """Issue a warning attributed to the user's line (the first caller outside mocaplab).

    Parameters
    ----------
    message : str or Warning
        The text (or a warning instance, whose class is then the category).
    category : type of Warning
        Default :class:`UserWarning`.

    Examples
    --------
    Package code calls ``warn("...", SomeWarning)`` wherever it is; the
    recorded ``filename`` and ``lineno`` are those of the user's call into
    the package (``tests/test_warnings_stacklevel.py`` checks this).
    """
    warnings.warn(message, category, stacklevel=user_stacklevel())
