"""Mass distribution estimation (Shin et al. 2003, section 3.2).

Captured clips are taken as physically plausible, so the link masses are
fitted to them: minimise, over the ground frames ``F_G`` of reference clips,
the distance ``f(m, t)`` of the ZMP outside the support polygon
(equation 5)::

    min_m  sum_{t in F_G} f(m, t)

with scipy's conjugate gradients (``scipy.optimize.minimize(method="CG")``)
from the anthropometric table (de Leva 1996) as initial guess.

Choices made here, where the paper leaves them open
---------------------------------------------------
* **Positivity** by parameterisation: ``m_i = m0_i exp(u_i)``, the
  optimiser works on the log-ratios ``u``.
* **Symmetry** (default on): left and right links share one parameter.
* **Regularisation**: the ZMP does not change when all masses are scaled,
  and equation 5 alone has degenerate minimisers (nearly all the mass in the
  stance foot puts the ZMP in the polygon), so a weak pull of the log-ratios
  towards the table, ``regularization * mean(u^2)`` (metres, like ``f``), is
  added; it also fixes the overall scale.  The result is rescaled to the
  initial total mass.
* The objective is the **mean** of ``f`` over the ground frames (same
  minimiser as the sum, scale-free in the number of frames); its gradient
  is analytic: ``f`` moves with the ZMP along the outward direction, and
  the polygon does not depend on the masses.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import OptimizeResult, minimize

from ..motion import Motion
from ..roles import resolve_roles
from .body import GRAVITY, Body, link_positions, paper_width, smoothed_derivatives
from .zmp import _check_contacts, ground_contacts, polygon_distance

if TYPE_CHECKING:  # pragma: no cover
    from ..contacts import Contacts

__all__ = ["MassFit", "fit_masses"]

Array = NDArray[np.float64]


@dataclasses.dataclass(frozen=True, eq=False)
class MassFit:
    """Result of :func:`fit_masses`.

    Parameters
    ----------
    body : Body
        The body with fitted masses (same total mass as the initial one).
    initial : Body
        The starting body (table masses).
    before, after : float
        Mean ZMP distance outside the support polygon over the ground frames
        of the reference clips, metres, with the initial and fitted masses.
    result : scipy.optimize.OptimizeResult
        The optimiser's report.

    Examples
    --------
    >>> import mocaplab as ml
    >>> fit = ml.physics.fit_masses(ml.cmu("16_15").resample(30)[:60])
    >>> round(fit.body.total_mass, 1) == round(fit.initial.total_mass, 1)
    True
    """

    body: Body
    initial: Body
    before: float
    after: float
    result: OptimizeResult

    def ratios(self) -> dict[str, float]:
        """Fitted over initial mass, per link."""
        return {n: float(a / b) for n, a, b in zip(self.body.link_names, self.body.masses, self.initial.masses, strict=True)}


@dataclasses.dataclass(frozen=True)
class _Frames:
    num: Array  # (N, L, 2): per-link numerator terms of Z_x, Z_z
    den: Array  # (N, L): per-link denominator terms
    support: Array  # (N, P, 2)
    active: NDArray[np.bool_]  # (N, P)


def _frames(motion: Motion, body: Body, contacts: Contacts) -> _Frames:
    """Mass-independent pieces of equation 4 on the ground frames of a clip."""
    r, _, acc = smoothed_derivatives(link_positions(motion, body), motion.fps, width=paper_width(5.0, motion.fps))
    a = acc - GRAVITY
    mask = np.asarray(contacts.mask, dtype=bool)
    ground = mask.any(axis=1)
    den = a[..., 1]
    # Z = sum_i m_i num_i / sum_i m_i den_i
    num = np.stack([den * r[..., 0] - a[..., 0] * r[..., 1], den * r[..., 2] - a[..., 2] * r[..., 1]], axis=-1)
    support, column = body.support_points(motion, contacts.joints)
    return _Frames(num[ground], den[ground], support[ground][..., [0, 2]], mask[ground][:, column])


def _objective(
    u: Array, frames: list[_Frames], base: Array, group: NDArray[np.int64], reg: float, weight: float, eps: float
) -> tuple[float, Array]:
    m = base * np.exp(u[group])
    total = 0.0
    grad_m = np.zeros_like(m)
    count = 0
    for fr in frames:
        den = fr.den @ m  # (N,)
        ok = den > 1e-3 * weight * m.sum() / base.sum()
        z = np.einsum("nlc,l->nc", fr.num, m) / np.where(ok, den, 1.0)[:, None]
        signed, proj = polygon_distance(np.where(ok[:, None], z, np.nan), fr.support, fr.active)
        valid = np.isfinite(signed)
        d = np.where(valid, np.maximum(signed, 0.0), 0.0)
        # Huber-smoothed distance: d^2 / (2 eps) below eps, d - eps / 2 above
        f = np.where(d < eps, d * d / (2.0 * eps), d - 0.5 * eps) if eps > 0 else d
        slope = np.minimum(d / eps, 1.0) if eps > 0 else (d > 0).astype(float)
        total += float(f.sum())
        count += int(valid.sum())
        out = valid & (signed > 0)
        if np.any(out):
            n = (z[out] - proj[out]) / signed[out, None] * slope[out, None]  # outward direction
            # dZ/dm_l = (num_l - Z den_l) / den
            dz = (fr.num[out] - z[out, None, :] * fr.den[out, :, None]) / den[out, None, None]
            grad_m += np.einsum("nc,nlc->l", n, dz)
    count = max(count, 1)
    value = total / count + reg * float(np.mean(u**2))
    grad_u_full = grad_m * m / count
    grad = np.bincount(group, weights=grad_u_full, minlength=u.size) + reg * 2.0 * u / u.size
    return value, grad


def fit_masses(
    motions: Motion | Sequence[Motion],
    body: Body | None = None,
    *,
    contacts: Contacts | Sequence[Contacts] | Literal["auto"] | None = "auto",
    symmetric: bool = True,
    regularization: float = 0.01,
    smoothing: float = 0.005,
    max_iterations: int = 200,
    roles: Mapping[str, Any] | None = None,
) -> MassFit:
    """Fit link masses so the ZMP stays in the support polygon (equation 5).

    Parameters
    ----------
    motions : Motion or sequence of Motion
        Reference clips believed physically plausible (captured, unedited),
        all with the body's skeleton.
    body : Body, optional
        Initial guess (default :meth:`Body.from_skeleton` of the first clip, measured
        in its standing pose when the rest pose does not stand).
    contacts : "auto", Contacts or sequence of Contacts
        One per clip; ``"auto"`` (default) detects each clip's
        (:func:`mocaplab.contacts.foot_contacts`).
    symmetric : bool
        Tie left and right links to one mass.
    regularization : float
        Weight of the pull of ``log(m / m0)`` towards 0 (metres).
    smoothing : float
        Huber width in metres: the distance is replaced by ``d^2 / (2 eps)``
        below ``eps`` so that the objective has a continuous gradient at the
        polygon's boundary (conjugate gradients stall on the kink); 0 uses
        the plain distance.  ``before``/``after`` report the plain distance.
    max_iterations : int
        Iteration cap of the conjugate-gradient solver.
    roles : mapping of role names to joint names, optional
        Role overrides (:func:`mocaplab.roles.resolve_roles`) for the
        default body and contacts (the clips share one skeleton).

    Returns
    -------
    MassFit
        ``.body`` with the fitted masses, ``.before`` and ``.after`` mean
        distances (metres).

    Examples
    --------
    The mean ZMP distance (mm) of two seconds of a walk, before and after:

    >>> import mocaplab as ml
    >>> fit = ml.physics.fit_masses(ml.cmu("16_15").resample(30)[:60])
    >>> round(1000 * fit.before, 1), round(1000 * fit.after, 1)
    (12.5, 6.0)
    """
    clips = [motions] if isinstance(motions, Motion) else list(motions)
    if not clips:
        raise ValueError("Expected at least one reference motion, got none")
    for k, m in enumerate(clips):
        if not isinstance(m, Motion):
            raise TypeError(f"Expected Motion objects in `motions`, got {type(m).__name__} at position {k}")
    known = resolve_roles(clips[0], roles) if body is None or isinstance(contacts, str) else None
    body = Body.from_skeleton(clips[0], roles=known) if body is None else body
    if contacts is None or isinstance(contacts, str):
        cons = [ground_contacts(contacts, m, roles=known) for m in clips]
    elif hasattr(contacts, "mask"):
        cons = [contacts]  # type: ignore[list-item]
    else:
        cons = list(contacts)  # type: ignore[arg-type]
    if len(cons) != len(clips):
        raise ValueError(f"Expected one Contacts per motion ({len(clips)}), got {len(cons)}")
    for m, c in zip(clips, cons, strict=True):
        body.check(m)
        _check_contacts(c, m)
    if not (np.isfinite(smoothing) and smoothing >= 0):
        raise ValueError(f"Expected `smoothing` >= 0 metres, got {smoothing!r}")
    if not (np.isfinite(regularization) and regularization >= 0):
        raise ValueError(f"Expected `regularization` >= 0, got {regularization!r}")
    frames = [_frames(m, body, c) for m, c in zip(clips, cons, strict=True)]
    if sum(f.den.shape[0] for f in frames) == 0:
        raise ValueError("The reference motions have no ground frame: nothing to fit the masses to")
    base = np.asarray(body.masses, dtype=float)
    if symmetric:
        mirror = body.mirror_map()
        rep = np.minimum(np.arange(body.n_links), mirror)
        _, group = np.unique(rep, return_inverse=True)
    else:
        group = np.arange(body.n_links)
    n_par = int(group.max()) + 1
    weight = float(base.sum() * np.linalg.norm(GRAVITY))

    def fun(u: Array) -> tuple[float, Array]:
        return _objective(u, frames, base, group, regularization, weight, smoothing)

    res = minimize(fun, np.zeros(n_par), jac=True, method="CG", options={"maxiter": int(max_iterations)})
    masses = base * np.exp(res.x[group])
    masses *= base.sum() / masses.sum()
    fitted = body.with_masses(masses)
    after = _objective(np.zeros(n_par), frames, fitted.masses, group, 0.0, weight, 0.0)[0]
    before = _objective(np.zeros(n_par), frames, base, group, 0.0, weight, 0.0)[0]
    return MassFit(fitted, body, float(before), float(after), res)
