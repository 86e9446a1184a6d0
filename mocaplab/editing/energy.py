"""Deformation energy of an edit (Kim et al. 2009, equation 10).

``E = E_shape + E_scale + E_time + c_s |L_s(P') - L_s(P)| + c_t |L_t(P') - L_t(P)|``

``E_shape``, ``E_scale`` and ``E_time`` are the least-squares objectives of the
three Laplacian systems at their solutions (:class:`Energies`); ``L_s`` is the
spatial path length and ``L_t`` the duration.  We sum the absolute length and
duration changes over characters.  Section 5's discrete optimisation
(:mod:`mocaplab.editing.graph`) compares this energy across candidate
transformations, so ``reference`` lets the original (untransformed) lengths
and durations be passed in.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["Energies", "deformation_energy", "path_lengths", "durations"]


@dataclasses.dataclass(frozen=True)
class Energies:
    """The three Laplacian energies of an edit (squared metres / seconds).

    Parameters
    ----------
    shape : float
        Phase 1 (shape-preserving) least-squares objective, m^2.
    scale : float
        Phase 2 (scale-compensation) objective, m^2.
    time : float
        Time-warp objective, s^2.

    Examples
    --------
    >>> Energies(0.5, 0.25, 0.125).total
    0.875
    """

    shape: float
    scale: float
    time: float

    @property
    def total(self) -> float:
        return self.shape + self.scale + self.time


def path_lengths(paths: Sequence[Any]) -> np.ndarray:
    """Arc length of each ``(F, 2)`` path, shape (K,)."""
    return np.array([float(np.sum(np.linalg.norm(np.diff(np.asarray(p), axis=0), axis=1))) for p in paths])


def durations(times: Sequence[Any]) -> np.ndarray:
    """Span ``t[-1] - t[0]`` of each time warp, shape (K,)."""
    return np.array([float(np.asarray(t)[-1] - np.asarray(t)[0]) for t in times])


def deformation_energy(
    result: Any,
    *,
    cs: float = 1.0,
    ct: float = 1.0,
    reference: tuple[Sequence[float], Sequence[float]] | None = None,
) -> float:
    """Equation 10 for an :class:`~mocaplab.editing.scene.EditResult`.

    Parameters
    ----------
    result : EditResult
    cs, ct : float
        Weights of the length (per metre) and duration (per second) terms.
    reference : (lengths, durations), optional
        Per-character path lengths and durations of the original paths ``P``
        (default: those of ``result``'s input characters).

    Returns
    -------
    float
        ``E_shape + E_scale + E_time + cs * sum |dL_s| + ct * sum |dL_t|``.

    Raises
    ------
    ValueError
        For ``reference`` lengths or durations of another number of characters.

    Examples
    --------
    Stretching a 4.3 m walk to end 1 m further costs about the length it
    gains (the Laplacian energies are near zero):

    >>> from mocaplab.data import cmu
    >>> from mocaplab.editing import PinPosition, edit
    >>> walk = cmu("16_15")
    >>> ends = walk.root_positions[[0, -1]][:, [0, 2]]
    >>> res = edit([walk], [PinPosition(0, 0, ends[0], hard=True), PinPosition(0, 470, ends[1] + (1.0, 0.0))])
    >>> round(deformation_energy(res), 3), round(deformation_energy(res, cs=0.0), 3)
    (0.099, 0.0)
    """
    e = result.energies
    if reference is None:
        ref_len = np.array([p.length for p in result.original_paths])
        ref_dur = np.array([(p.n_frames - 1) / p.fps for p in result.original_paths])
    else:
        ref_len = np.asarray(reference[0], dtype=float)
        ref_dur = np.asarray(reference[1], dtype=float)
    ls = path_lengths(result.paths)
    lt = durations(result.times)
    if ref_len.shape != ls.shape or ref_dur.shape != lt.shape:
        raise ValueError(f"Expected `reference` lengths and durations for {len(ls)} characters")
    return float(e.total + cs * np.sum(np.abs(ls - ref_len)) + ct * np.sum(np.abs(lt - ref_dur)))
