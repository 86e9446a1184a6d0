"""One BLAS thread around the editors' solves.

The systems an interactive editor solves on every drag are small (dense
blocks of a few hundred unknowns, sparse factors of a few thousand): a
multi-threaded BLAS spends more on waking and synchronising its threads than
on the arithmetic, and competes with the notebook's own work.
:func:`single_blas_thread` limits the BLAS libraries loaded in the process
(numpy's, scipy's) to one thread for the duration of a ``with`` block and
restores the caller's setting afterwards, whatever it was.

One :class:`threadpoolctl.ThreadpoolController` is made on first use (it
inspects the loaded libraries once, ~2 ms); entering and leaving the block
then costs tens of microseconds.
"""

from __future__ import annotations

from contextlib import AbstractContextManager
from typing import Any

__all__ = ["single_blas_thread"]

_controller: Any = None


def single_blas_thread() -> AbstractContextManager[Any]:
    """A context manager running its block under one BLAS thread (the caller's limits restored on exit).

    Examples
    --------
    >>> with single_blas_thread():
    ...     pass
    """
    global _controller
    if _controller is None:
        from threadpoolctl import ThreadpoolController

        _controller = ThreadpoolController()
    return _controller.limit(limits=1, user_api="blas")
