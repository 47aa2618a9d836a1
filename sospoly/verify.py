"""Certification by verification: the degree-2 certificate without an SDP.

For a quadratic f and quadratic equalities g (no inequalities), the degree-2
Positivstellensatz certificate with q = 1 reads u(v) = f(v) - c + lambda^T g(v) SOS
with constant multipliers lambda.  A quadratic is SOS iff it is a non-negative
quadratic form, so for a *given* lambda the best c is

    c(lambda) = min_v L(v, lambda),   L = f + lambda^T g   (Lagrangian duality),

finite iff the Hessian H of L is PSD and the gradient of L at 0 lies in range(H).
Any such lambda gives a valid lower bound c(lambda) <= min{f : g = 0}.

Given a candidate minimiser v^ (e.g. from a local solver), lambda is recovered
from the KKT conditions grad f(v^) + J(v^)^T lambda = 0 by least squares; the bound
is then computed from the exact polynomial data (never from the local solver's
word): H must have lambda_min(H) >= -ROUNDOFF * max(1, |H|), c(lambda) is the
minimum of the quadratic L, evaluated with a least-squares solve and checked by
the residual of the stationarity system.  When f(v^) - c(lambda) is within the
optimality tolerance, v^ is certified globally optimal exactly as the degree-2
SDP would certify it; otherwise the caller falls back to the SDP.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .polynomial import Polynomial
from .status import SolveStatus
from .tolerances import DEFAULT_TOLERANCES, Tolerances

__all__ = ["Verification", "quadratic_parts", "verify_quadratic", "ROUNDOFF"]

#: the Lagrangian Hessian must satisfy lambda_min >= -ROUNDOFF * max(1, max|H|): float
#: round-off only (a genuinely indefinite H means no bound for these multipliers).
ROUNDOFF = 1e-12


@dataclass(frozen=True)
class Verification:
    status: SolveStatus          # OPTIMAL when a bound was computed and checked
    lower_bound: float | None
    upper_bound: float | None    # f(v^)
    certified: bool
    multipliers: np.ndarray | None
    min_hessian_eigenvalue: float | None
    message: str = ""


def quadratic_parts(p: Polynomial, gens) -> tuple[float, np.ndarray, np.ndarray]:
    """(p0, p1, P2) with p(v) = p0 + p1.v + v^T P2 v for a polynomial of degree <= 2."""
    p = p.with_gens(gens)
    if p.degree > 2:
        raise ValueError(f"quadratic_parts needs degree <= 2, got {p.degree}")
    n = len(gens)
    p0, p1, P2 = 0.0, np.zeros(n), np.zeros((n, n))
    for e, c in p.terms.items():
        nz = [k for k, v in enumerate(e) if v]
        if not nz:
            p0 += c
        elif len(nz) == 1 and e[nz[0]] == 1:
            p1[nz[0]] += c
        elif len(nz) == 1:
            P2[nz[0], nz[0]] += c
        else:
            i, j = nz
            P2[i, j] += c / 2
            P2[j, i] += c / 2
    return p0, p1, P2


def verify_quadratic(f: Polynomial, eq, point, *, gens=None,
                     tolerances: Tolerances = DEFAULT_TOLERANCES) -> Verification:
    """Lagrangian lower bound at a candidate ``point`` (see module docstring)."""
    gens = tuple(gens or f.gens)
    v = np.asarray(point, float)
    f0, f1, F2 = quadratic_parts(f, gens)
    parts = [quadratic_parts(g, gens) for g in eq]
    fv = float(f0 + f1 @ v + v @ F2 @ v)
    if not parts:
        lam = np.zeros(0)
    else:
        J = np.array([p1 + 2 * P2 @ v for _, p1, P2 in parts])        # rows: grad g_k(v)
        grad_f = f1 + 2 * F2 @ v
        lam, *_ = np.linalg.lstsq(J.T, -grad_f, rcond=None)
    L0 = f0 + sum(l * p0 for l, (p0, _, _) in zip(lam, parts))
    L1 = f1 + sum((l * p1 for l, (_, p1, _) in zip(lam, parts)), np.zeros_like(f1))
    L2 = F2 + sum((l * P2 for l, (_, _, P2) in zip(lam, parts)), np.zeros_like(F2))
    eig = np.linalg.eigvalsh(L2)
    scale = max(1.0, float(np.max(np.abs(L2))))
    if eig[0] < -ROUNDOFF * scale:
        return Verification(SolveStatus.INFEASIBLE, None, fv, False, lam, float(eig[0]),
                            "Lagrangian Hessian is not PSD: no degree-2 certificate with these multipliers")
    # min of L0 + L1.v + v^T L2 v: stationary point 2 L2 w = -L1 (least squares), checked
    w, *_ = np.linalg.lstsq(2 * L2, -L1, rcond=None)
    resid = np.linalg.norm(2 * L2 @ w + L1) / max(1.0, np.linalg.norm(L1))
    if resid > tolerances.identity_residual:
        return Verification(SolveStatus.INFEASIBLE, None, fv, False, lam, float(eig[0]),
                            "gradient of the Lagrangian not in range(H): unbounded below")
    c = float(L0 + L1 @ w + w @ L2 @ w)
    certified = tolerances.certified(c, fv)
    return Verification(SolveStatus.OPTIMAL, c, fv, certified, lam, float(eig[0]),
                        "" if certified else "gap above tolerance")
