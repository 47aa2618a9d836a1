"""Certification by verification: the degree-2 certificate without an SDP.

For a quadratic f and quadratic equalities g (no inequalities), the degree-2
Positivstellensatz certificate with q = 1 reads u(v) = f(v) - c + lambda^T g(v) SOS
with constant multipliers lambda.  A quadratic is SOS iff it is a non-negative
quadratic form, so for a *given* lambda the best c is

    c(lambda) = min_v L(v, lambda),   L = f + lambda^T g   (Lagrangian duality),

finite iff the Hessian H of L is PSD and the gradient of L at 0 lies in range(H).
Any such lambda gives a valid lower bound c(lambda) <= min{f : g = 0}.

Given a candidate minimiser v^ (e.g. from a local solver), lambda is recovered
from the KKT conditions grad f(v^) + J(v^)^T lambda = 0 by least squares (again with a
truncated SVD where dependent constraints leave J^T a singular value at round-off); the bound
is then computed from the exact polynomial data (never from the local solver's
word): H must have lambda_min(H) >= -ROUNDOFF * max(|F2|, |H|) (relative to the
program's own quadratic terms: scaling f, or the variables, scales both sides), c(lambda)
is the minimum of the quadratic L, evaluated with a least-squares solve and checked by
the residual of the stationarity system.  When f(v^) - c(lambda) is within the
optimality tolerance at the objective's own scale (its largest coefficient, as
:func:`sospoly.minimize` measures it), v^ is certified globally optimal exactly as the
degree-2 SDP would certify it; otherwise the caller falls back to the SDP.  (A floor of 1 in
either test made both absolute for programs of small scale: the maximiser of 1e-13 (x + y)
on the unit circle was certified as its minimum, review 21a F1.)

:func:`verify_quadratic_batch` runs the same test on a stack of M programs with one
structure (n variables, K equalities), every step vectorised with numpy over the
stack; :func:`verify_quadratic` is that function applied to a stack of one (which runs the
scalar twin of the same steps on plain arrays: the same decision rule, equal up to round-off).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..algebra.polynomial import Polynomial
from ..status import SolveStatus
from ..tolerances import DEFAULT_TOLERANCES, Tolerances

__all__ = ["Verification", "VerificationBatch", "SparseQuadratics", "quadratic_parts", "verify_quadratic",
           "verify_quadratic_batch", "bound_at_one", "objective_scales", "objective_scale_one", "free_margins",
           "stationary", "ROUNDOFF", "RETRY_RCOND"]

#: the Lagrangian Hessian must satisfy lambda_min >= -ROUNDOFF * max(max|F2|, max|H|): float
#: round-off only (a genuinely indefinite H means no bound for these multipliers).
ROUNDOFF = 1e-12


@dataclass(frozen=True)
class Verification:
    """The outcome of :func:`verify_quadratic` for one program (a :class:`VerificationBatch` item)."""
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


@dataclass(frozen=True)
class VerificationBatch:
    """:class:`Verification` of M programs, one array entry per program.

    ``lower_bound`` is NaN where no bound was computed; ``reason`` is 0 (bound computed),
    1 (Lagrangian Hessian not PSD) or 2 (gradient of the Lagrangian not in range(H)).
    """
    lower_bound: np.ndarray            # (M,)
    upper_bound: np.ndarray            # (M,) f(v^)
    certified: np.ndarray              # (M,) bool
    multipliers: np.ndarray            # (M, K)
    min_hessian_eigenvalue: np.ndarray  # (M,)
    reason: np.ndarray                 # (M,) int

    MESSAGES = ("", "Lagrangian Hessian is not PSD: no degree-2 certificate with these multipliers",
                "gradient of the Lagrangian not in range(H): unbounded below")

    def __len__(self) -> int:
        return len(self.certified)

    def item(self, i: int) -> Verification:
        """The :class:`Verification` of program ``i``."""
        reason = int(self.reason[i])
        bounded = reason == 0
        certified = bool(self.certified[i])
        msg = self.MESSAGES[reason] if reason else ("" if certified else "gap above tolerance")
        return Verification(SolveStatus.OPTIMAL if bounded else SolveStatus.INFEASIBLE,
                            float(self.lower_bound[i]) if bounded else None, float(self.upper_bound[i]),
                            certified, self.multipliers[i].copy(), float(self.min_hessian_eigenvalue[i]), msg)


#: machine epsilon of float64 (twice the unit round-off).
_EPS = float(np.finfo(float).eps)


def _row_norms(a: np.ndarray) -> np.ndarray:
    """``numpy.linalg.norm(a, axis=1)`` of a real 2-D array by its own operations, sqrt(add.reduce(a * a)), without
    its per-call overhead: bit-identical."""
    return np.sqrt(np.add.reduce(a * a, axis=1))


def _svd_solve(U: np.ndarray, S: np.ndarray, Vt: np.ndarray, b: np.ndarray, rcond: float) -> np.ndarray:
    """x = V diag(1 / S) U^T b over the singular values S > rcond * max(S) of a stack's SVD (the others as zero)."""
    cut = rcond * S[:, :1]
    inv = np.where(S > cut, 1.0 / np.where(S > cut, S, 1.0), 0.0)
    return np.einsum("mji,mj->mi", Vt, inv * np.einsum("mpj,mp->mj", U, b))


#: the relative cut-off of the second multipliers (:func:`verify_quadratic_batch`): sqrt(eps).  Where equality
#: constraints are dependent at every feasible point (e.g. six of rank five, a common case of pairwise constraints),
#: J^T has a singular value at round-off; where it lands just above lstsq's cut-off (eps * max(p, q), ~1e-15), its
#: direction gets a multiplier ~ |grad f| / 1e-15 that breaks the Lagrangian Hessian.  Any multipliers give a valid
#: bound, so a program not certified by the minimum-norm ones is tried again with those directions dropped.
RETRY_RCOND = math.sqrt(_EPS)


def _first_rcond(n: int, K: int) -> float:
    """The minimum-norm multipliers' relative cut-off for J^T (n, K): ``numpy.linalg.lstsq(rcond=None)``'s rule,
    eps * max(n, K)."""
    return _EPS * max(n, K)


def _retried(S: np.ndarray, first: float) -> np.ndarray:
    """(M,) bool: rows of singular values S (M, r), descending, with one kept by the cut-off ``first`` and dropped by
    :data:`RETRY_RCOND` (where the second multipliers differ from the first)."""
    return np.any((S > first * S[:, :1]) & (S <= RETRY_RCOND * S[:, :1]), axis=1)


@dataclass(frozen=True)
class SparseQuadratics:
    """The quadratic parts G2[m, k] of K constraints over a stack of M programs, stored as one entry pattern
    (constraint ``k``, row ``i``, column ``j``; both triangles listed for off-diagonal entries) shared by the
    stack and the values ``vals`` (M, nnz)."""
    k: np.ndarray
    i: np.ndarray
    j: np.ndarray
    vals: np.ndarray

    @classmethod
    def from_dense(cls, G2: np.ndarray) -> SparseQuadratics:
        nz = np.nonzero(np.any(G2 != 0, axis=0))
        return cls(nz[0], nz[1], nz[2], G2[:, nz[0], nz[1], nz[2]])

    def apply(self, v: np.ndarray, K: int, n: int) -> np.ndarray:
        """(M, K, n): G2[m, k] @ v[m] for every k."""
        out = np.zeros((v.shape[0], K, n))
        np.add.at(out, (slice(None), self.k, self.i), self.vals * v[:, self.j])
        return out

    def combine(self, lam: np.ndarray, n: int) -> np.ndarray:
        """(M, n, n): sum_k lam[m, k] G2[m, k]."""
        out = np.zeros((lam.shape[0], n, n))
        np.add.at(out, (slice(None), self.i, self.j), self.vals * lam[:, self.k])
        return out

    def rows(self, idx) -> SparseQuadratics:
        """The programs ``idx`` of the stack (the same entry pattern)."""
        return SparseQuadratics(self.k, self.i, self.j, self.vals[idx])


def verify_quadratic_batch(f0, f1, F2, g0, g1, G2, points, *,
                           tolerances: Tolerances = DEFAULT_TOLERANCES, radius=None,
                           constraint_error=None) -> VerificationBatch:
    """The Lagrangian bound of the module docstring for M programs at once.

    Program m: f(v) = f0[m] + f1[m].v + v^T F2[m] v and g_k(v) = g0[m,k] + g1[m,k].v +
    v^T G2[m,k] v (k < K), candidate v^ = points[m].  Shapes: f0 (M,), f1 (M, n),
    F2 (M, n, n), g0 (M, K), g1 (M, K, n), G2 (M, K, n, n), points (M, n); F2, G2 symmetric.
    ``G2`` may also be given sparsely, as a :class:`SparseQuadratics` (one entry pattern shared by the
    stack, values per program): memory O(M (K n + n^2)) instead of O(M K n^2).

    Steps, all vectorised over m: lambda = argmin ||J(v^)^T lambda + grad f(v^)|| (min-norm
    least squares; a program these do not certify is tried again with the singular values of J^T below
    :data:`RETRY_RCOND` s_max dropped, the larger of the two valid bounds kept); L = f + lambda^T g
    with Hessian part L2; reject when lambda_min(L2) < -ROUNDOFF * max(max|F2|, max|L2|); w = least-squares solution of
    2 L2 w = -L1, rejected when ||2 L2 w + L1|| / max(min(1, s_f), ||L1||) > identity_residual, s_f the
    objective's largest coefficient (:func:`objective_scales`); c = L(w) = min_v L(v, lambda) <= min{f : g = 0};
    certified iff ``tolerances.certified(c, f(v^), s_f)`` (the rule at the objective's own scale).

    ``radius`` (scalar or (M,)): a bound on the norm of a minimiser.  The bound is then made rigorous
    against the accepted round-off: with eps = max(0, -lambda_min(L2)) and the stationarity residual
    r = 2 L2 w + L1, L(v) >= L(w) - eps ||v - w||^2 - ||r|| ||v - w|| for every v, so on the ball
    c - eps (R + ||w||)^2 - ||r|| (R + ||w||) - 8 eps_mach (|L0| + |L1.w| + |w^T L2 w|) is a lower bound.
    Without a radius (None) there is no ball to charge these to: a bound is given only where L2 is positive
    definite beyond round-off, c - ||r||^2 / (4 mu) - 8 eps_mach (...) with mu > 0 (:func:`free_margins`); elsewhere
    none (reason 1), however close lambda_min(L2) is to 0.

    ``constraint_error`` ((M, K)): e_k >= |g_k(v)| at the ball's points feasible for the caller's *true* constraints,
    of which the g_k given are computed approximations; the bound is then c - sum_k |lambda_k| e_k
    (:func:`constraint_margin`: lambda multiplies the data's error, and reaches 1e13 at a degenerate candidate).
    A stack of one (M = 1) runs the scalar twin of these steps (plain arrays, matrix products instead of the
    stack's einsum, the same margin): equal to the stacked code up to round-off, not bit for bit."""
    f0 = np.asarray(f0, float)
    f1 = np.asarray(f1, float)
    F2 = np.asarray(F2, float)
    g0 = np.asarray(g0, float)
    g1 = np.asarray(g1, float)
    v = np.asarray(points, float)
    M, n = f1.shape
    K = g0.shape[1]
    G2 = G2 if isinstance(G2, SparseQuadratics) else SparseQuadratics.from_dense(np.asarray(G2, float)) \
        if np.asarray(G2).shape == (M, K, n, n) else np.asarray(G2)
    if F2.shape != (M, n, n) or g1.shape != (M, K, n) or v.shape != (M, n) or f0.shape != (M,) or g0.shape != (M, K) \
            or not isinstance(G2, SparseQuadratics) or G2.vals.shape[0] != M:
        raise ValueError(f"verify_quadratic_batch: inconsistent shapes f0 {f0.shape}, f1 {f1.shape}, F2 {F2.shape}, "
                         f"g0 {g0.shape}, g1 {g1.shape}, "
                         f"G2 {G2.vals.shape if isinstance(G2, SparseQuadratics) else np.shape(G2)}, "
                         f"points {v.shape}")
    err = None if constraint_error is None else np.broadcast_to(np.asarray(constraint_error, float), (M, K))
    if M == 1:
        return _verify_one(f0[0], f1[0], F2[0], g0[0], g1[0], G2, v[0], tolerances,
                           None if radius is None else float(np.broadcast_to(np.asarray(radius, float), (1,))[0]),
                           None if err is None else err[0])
    fv = f0 + np.einsum("mi,mi->m", f1, v) + np.einsum("mi,mij,mj->m", v, F2, v)
    grad_f = f1 + 2 * np.einsum("mij,mj->mi", F2, v)
    if not K:
        return _bounds_at(f0, f1, F2, g0, g1, G2, np.zeros((M, 0)), fv, tolerances, radius, err)
    J = g1 + 2 * G2.apply(v, K, n)                                      # rows: grad g_k(v)
    svd = np.linalg.svd(np.swapaxes(J, 1, 2), full_matrices=False)
    first = _first_rcond(n, K)
    out = _bounds_at(f0, f1, F2, g0, g1, G2, _svd_solve(*svd, -grad_f, first), fv, tolerances, radius, err)
    again = np.nonzero(~out.certified & _retried(svd[1], first))[0]
    if not again.size:
        return out
    lam = _svd_solve(*(a[again] for a in svd), -grad_f[again], RETRY_RCOND)
    sub = _bounds_at(f0[again], f1[again], F2[again], g0[again], g1[again], G2.rows(again), lam, fv[again], tolerances,
                     None if radius is None else np.broadcast_to(np.asarray(radius, float), (M,))[again],
                     None if err is None else err[again])
    return _better(out, sub, again)


def _bounds_at(f0, f1, F2, g0, g1, G2, lam, fv, tolerances, radius, err) -> VerificationBatch:
    """The stack's Lagrangian bounds c(lambda) at the multipliers ``lam`` (M, K), made rigorous, and the certificate
    rule against the candidates' values ``fv`` (the steps of :func:`verify_quadratic_batch` after lambda)."""
    n = f1.shape[1]
    L0 = f0 + np.einsum("mk,mk->m", lam, g0)
    L1 = f1 + np.einsum("mk,mki->mi", lam, g1)
    L2 = F2 + G2.combine(lam, n)
    eig, Q = np.linalg.eigh(L2)
    scale = np.maximum(np.max(np.abs(F2), axis=(1, 2)), np.max(np.abs(L2), axis=(1, 2)))
    psd = eig[:, 0] >= -ROUNDOFF * scale
    s_f = objective_scales(f0, f1, F2)
    # min of L0 + L1.v + v^T L2 v: stationary point 2 L2 w = -L1 by least squares (the
    # pseudo-inverse of the symmetric 2 L2 from its eigen-decomposition, lstsq's cut-off)
    s = 2 * eig
    abs_s = np.abs(s)
    cut = _EPS * n * np.max(abs_s, axis=1, keepdims=True)
    inv = np.where(abs_s > cut, 1.0 / np.where(abs_s > cut, s, 1.0), 0.0)
    w = -np.einsum("mij,mj->mi", Q, inv * np.einsum("mji,mj->mi", Q, L1))
    r_abs = _row_norms(2 * np.einsum("mij,mj->mi", L2, w) + L1)          # the stationarity residual ||2 L2 w + L1||
    in_range = stationary(r_abs, _row_norms(L1), s_f, tolerances)
    t1, t2 = np.einsum("mi,mi->m", L1, w), np.einsum("mi,mij,mj->m", w, L2, w)
    c = _with_margins(L0 + t1 + t2, (L0, t1, t2), eig[:, 0], r_abs, _row_norms(w), radius, lam, err)
    if radius is None:                  # no ball: positive definite beyond round-off, the residual's exact margin
        hess = _row_norms(F2.reshape(len(F2), -1)) + np.add.reduce(np.abs(G2.vals * lam[:, G2.k]), axis=1)
        margin, definite = free_margins(eig[:, 0], hess, n, r_abs)
        c, psd = c - margin, psd & definite
    reason = np.where(~psd, 1, np.where(~in_range, 2, 0))
    bounded = reason == 0
    lower = np.where(bounded, c, np.nan)
    certified = bounded & np.asarray(tolerances.certified(lower, fv, s_f), bool)
    return VerificationBatch(lower, fv, certified, lam, eig[:, 0], reason)


def _better(out: VerificationBatch, sub: VerificationBatch, rows: np.ndarray) -> VerificationBatch:
    """``out`` with its ``rows`` replaced by those of ``sub`` (a second try at them) where ``sub``'s bound is higher
    (a bound where ``out`` has none): both are valid bounds, the larger is kept with its multipliers."""
    take = ~(sub.lower_bound <= out.lower_bound[rows]) & ~np.isnan(sub.lower_bound)
    if not take.any():
        return out
    r = rows[take]
    fields = {}
    for name in ("lower_bound", "upper_bound", "certified", "multipliers", "min_hessian_eigenvalue", "reason"):
        a = getattr(out, name).copy()
        a[r] = getattr(sub, name)[take]
        fields[name] = a
    return VerificationBatch(**fields)


def _with_margins(c, terms, eig0, r_abs, w_norm, radius, lam, err):
    """The stack's bounds c made rigorous (:func:`verify_quadratic_batch`'s docstring): on the ball of ``radius``
    the round-off margins of the accepted Hessian, stationarity residual and sums, then the constraint data's
    error (``err``: None, or (M, K))."""
    L0, t1, t2 = terms
    rounding = 8 * _EPS * (np.abs(L0) + np.abs(t1) + np.abs(t2))
    if radius is not None:
        c = c - _margin_terms(np.maximum(0.0, -eig0), r_abs, np.asarray(radius, float) + w_norm) - rounding
    else:                               # (without a ball the caller adds free_margins')
        c = c - rounding
    return c if err is None else c - constraint_margin(lam, err)


def _margin_terms(defect, r_abs, reach):
    """defect reach^2 + ||r|| reach, each term 0 where its factor is (a huge or infinite ball leaves an exact
    Lagrangian bound as it is: 0 * inf is not a margin), inf past the largest float (products, never ``**``)."""
    with np.errstate(over="ignore", invalid="ignore"):
        return np.where(defect > 0, defect * reach * reach, 0.0) + np.where(r_abs > 0, r_abs * reach, 0.0)


def free_margins(eig0, hess_scale, n: int, r_abs):
    """(margin, ok) of a bound without a ball (``radius=None``): L2 must be positive definite beyond the
    eigensolver's and the assembly's round-off, mu = lambda_min(L2) - 16 n eps_mach A > 0 (A = ``hess_scale`` >=
    ||F2||_F + sum_k |lambda_k| ||G2_k||_F); then L(v) >= L(w) + r . (v - w) + mu ||v - w||^2 >= L(w) - ||r||^2 / (4 mu)
    for every v, r = 2 L2 w + L1 the stationarity residual.  Where L2 is only positive semidefinite up to round-off
    a direction of (near) zero curvature may carry a linear term and L is then unbounded below: no bound (ok False;
    review 38a H1: 1e8 x^2 + 1e-5 y on y^2 = 1 was certified at +1e-5 from its maximiser, the minimum is -1e-5).
    Scalars or arrays."""
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        mu = np.asarray(eig0, float) - 16 * n * _EPS * np.asarray(hess_scale, float)
        ok = mu > 0
        margin = np.where(ok, np.asarray(r_abs, float) ** 2 / np.where(ok, 4 * mu, 1.0), np.inf)
    return margin, ok


#: the denominator's floor of the stationarity test (a zero L1 and residual: in range)
_TINY = 1e-300


def stationary(r_abs, l1_norm, s_f, tolerances: Tolerances):
    """The stationarity test of the Lagrangian's minimiser w (every verification, dense or banded): the residual
    ||2 L2 w + L1|| over max(min(1, s_f), ||L1||) within ``identity_residual``, s_f the objective's scale
    (:func:`objective_scales`) -- relative at any scale (a floor of 1 made it absolute below scale 1)."""
    return r_abs / np.maximum(np.minimum(1.0, s_f), np.maximum(l1_norm, _TINY)) <= tolerances.identity_residual


def objective_scales(f0, f1, F2) -> np.ndarray:
    """s_f (M,): the largest absolute coefficient of each program's objective f0 + f1.v + v^T F2 v (F2 counts twice
    off the diagonal, as the polynomial's coefficient), the scale of the certificate rule (:mod:`sospoly.tolerances`)
    and of the stationarity test."""
    f0, f1, F2 = np.atleast_1d(f0), np.atleast_2d(f1), np.asarray(F2, float).reshape((-1,) + np.shape(F2)[-2:])
    off = 2 * np.max(np.abs(F2 - np.einsum("mii->mi", F2)[:, :, None] * np.eye(F2.shape[-1])), axis=(1, 2),
                     initial=0.0)
    diag = np.max(np.abs(np.einsum("mii->mi", F2)), axis=1, initial=0.0)
    return np.maximum.reduce([np.abs(f0), np.max(np.abs(f1), axis=1, initial=0.0), diag, off])


def objective_scale_one(f0: float, f1: np.ndarray, F2: np.ndarray) -> float:
    """The scalar twin of :func:`objective_scales` for one program (f0 float, f1 (n,), F2 (n, n)): the same largest
    absolute coefficient (maxima are exact, so the same number) without the stack's einsum and identity; non-finite
    data take :func:`objective_scales` itself (its NaN propagation)."""
    A = np.abs(F2)
    g = np.abs(f1)
    if not (math.isfinite(f0) and np.isfinite(A).all() and np.isfinite(g).all()):
        return float(objective_scales(f0, f1, F2)[0])
    d = A.diagonal()
    off = 2 * float((A - np.diag(d)).max()) if A.size else 0.0
    return max(abs(f0), float(g.max()) if g.size else 0.0, float(d.max()) if d.size else 0.0, off)


def constraint_margin(lam, err) -> np.ndarray:
    """sum_k |lambda_k| e_k over the last axis, rounded up (the effect of constraint data known to within e_k on a
    Lagrangian bound, :func:`verify_quadratic_batch`)."""
    lam, err = np.abs(np.asarray(lam, float)), np.asarray(err, float)
    return np.sum(lam * err, axis=-1) * (1.0 + 4 * lam.shape[-1] * _EPS) if lam.shape[-1] else np.zeros(lam.shape[:-1])


def _verify_one(f0: float, f1, F2, g0, g1, G2: SparseQuadratics, v, tolerances: Tolerances,
                radius: float | None, constraint_error=None) -> VerificationBatch:
    """The scalar (M = 1) twin of :func:`verify_quadratic_batch`: the same steps on one program with plain
    (n,), (K, n), (n, n) arrays and matrix products instead of the stack's einsum; equal to it up to round-off
    (tests/test_scalar_twins.py), the same rigorous margin.  Returns a :class:`VerificationBatch` of one."""
    n, K = len(v), len(g0)
    fv = f0 + f1 @ v + v @ F2 @ v
    grad_f = f1 + 2 * (F2 @ v)
    if not K:
        return bound_at_one(f0, f1, F2, g0, g1, G2, np.zeros(0), fv, tolerances, radius, constraint_error)
    J = g1 + 2 * np.bincount(G2.k * n + G2.i, G2.vals[0] * v[G2.j], K * n).reshape(K, n)   # rows: grad g_k(v)
    U, S, Vt = np.linalg.svd(J.T, full_matrices=False)
    first = _first_rcond(n, K)
    out = bound_at_one(f0, f1, F2, g0, g1, G2, _svd_solve_one(U, S, Vt, -grad_f, first), fv, tolerances, radius,
                       constraint_error)
    if out.certified[0] or not _retried(S[None], first)[0]:
        return out
    sub = bound_at_one(f0, f1, F2, g0, g1, G2, _svd_solve_one(U, S, Vt, -grad_f, RETRY_RCOND), fv, tolerances,
                       radius, constraint_error)             # (the second multipliers of verify_quadratic_batch)
    return _better(out, sub, np.zeros(1, int))


def _svd_solve_one(U: np.ndarray, S: np.ndarray, Vt: np.ndarray, b: np.ndarray, rcond: float) -> np.ndarray:
    """The scalar twin of :func:`_svd_solve`."""
    cut = rcond * S[0]
    inv = np.where(S > cut, 1.0 / np.where(S > cut, S, 1.0), 0.0)
    return (inv * (b @ U)) @ Vt


def bound_at_one(f0: float, f1, F2, g0, g1, G2: SparseQuadratics, lam, fv: float, tolerances: Tolerances,
                 radius: float | None, constraint_error=None) -> VerificationBatch:
    """The Lagrangian bound c(lambda) = min_v L(v, lambda) of one program at the given multipliers ``lam`` (K,),
    with the rigorous margin of :func:`verify_quadratic_batch` on the ball of ``radius`` and the certificate rule
    against the value ``fv`` of a feasible point (the second half of :func:`_verify_one`; also the bound of
    multipliers found by :func:`sospoly.analysis.lagrangian.ascend_one`; ``constraint_error`` as there).  A
    :class:`VerificationBatch` of one."""
    n = len(f1)
    lam = np.asarray(lam, float)
    L0, L1 = f0 + lam @ g0, f1 + lam @ g1
    L2 = F2 + np.bincount(G2.i * n + G2.j, G2.vals[0] * lam[G2.k], n * n).reshape(n, n)
    eig, Q = np.linalg.eigh(L2)
    psd = bool(eig[0] >= -ROUNDOFF * max(float(np.max(np.abs(F2))), float(np.max(np.abs(L2)))))  # (NaN: not PSD)
    s_f = objective_scale_one(float(f0), f1, F2)
    s = 2 * eig
    cut = _EPS * n * np.max(np.abs(s))
    inv = np.where(np.abs(s) > cut, 1.0 / np.where(np.abs(s) > cut, s, 1.0), 0.0)
    w = -(Q @ (inv * (L1 @ Q)))
    r_abs = math.sqrt(float(np.sum((2 * (L2 @ w) + L1) ** 2)))
    in_range = bool(stationary(r_abs, math.sqrt(float(L1 @ L1)), s_f, tolerances))
    t1, t2 = float(L1 @ w), float(w @ L2 @ w)
    c = L0 + t1 + t2
    rounding = 8 * _EPS * (abs(L0) + abs(t1) + abs(t2))
    if radius is not None:
        c = c - float(_margin_terms(max(0.0, -float(eig[0])), r_abs, radius + math.sqrt(float(w @ w)))) - rounding
    else:                               # no ball: positive definite beyond round-off (free_margins)
        hess = math.sqrt(float(np.sum(F2 * F2))) + float(np.sum(np.abs(G2.vals[0] * lam[G2.k])))
        margin, definite = free_margins(float(eig[0]), hess, n, r_abs)
        c, psd = c - rounding - float(margin), psd and bool(definite)
    if constraint_error is not None:
        c = c - float(constraint_margin(lam, np.broadcast_to(np.asarray(constraint_error, float), lam.shape)))
    reason = 1 if not psd else 2 if not in_range else 0
    lower = np.array([c if reason == 0 else np.nan])
    fv = np.array([fv])
    certified = (reason == 0) & np.asarray(tolerances.certified(lower, fv, s_f), bool)
    return VerificationBatch(lower, fv, certified, lam[None], eig[:1].copy(), np.array([reason]))


def verify_quadratic(f: Polynomial, eq, point, *, gens=None,
                     tolerances: Tolerances = DEFAULT_TOLERANCES, radius: float | None = None,
                     constraint_error=None) -> Verification:
    """Lagrangian lower bound at a candidate ``point`` (see module docstring):
    :func:`verify_quadratic_batch` on a stack of one program (``radius``: a bound on the norm of a
    minimiser, which makes the bound rigorous; ``constraint_error`` (K,): as there)."""
    gens = tuple(gens or f.gens)
    n = len(gens)
    v = np.asarray(point, float)
    f0, f1, F2 = quadratic_parts(f, gens)
    parts = [quadratic_parts(g, gens) for g in eq]
    K = len(parts)
    g0 = np.array([[p[0] for p in parts]]).reshape(1, K)
    g1 = np.array([p[1] for p in parts]).reshape(1, K, n)
    G2 = np.array([p[2] for p in parts]).reshape(1, K, n, n)
    batch = verify_quadratic_batch(np.array([f0]), f1[None], F2[None], g0, g1, G2, v[None], tolerances=tolerances,
                                   radius=None if radius is None else np.array([float(radius)]),
                                   constraint_error=None if constraint_error is None else
                                   np.asarray(constraint_error, float).reshape(1, K))
    return batch.item(0)
