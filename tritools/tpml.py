"""TPML-style baseline: the SOS relaxation in the scene point's own coordinates (world domain).

The paper's Tables 8-11 compare with TPML (Chesi & Hung 2011), an SOS relaxation over the scene point
X itself.  Here the world-domain problem is written as a *sum of ratios* and handed to
:func:`sospoly.minimize_ratios` (Bugarin-Henrion-Lasserre certificates; the TPML program itself is
not public, so N_LMIVAR differs, see below).  With x_i = Phi(X, P_i) = u_i / s_i, u_i = P_i[:2] X~,
s_i = P_i[2] X~, and a region of paper eqs. (13)-(14) (f_i quadratic in x_i, auxiliaries y_i):

    d(x_i, R_i)^2 = min_{y_i} f_i(x_i, y_i),     f_i(u_i / s_i, y_i) = p_i(X, y_i) / s_i(X)^2,

p_i the homogenisation of f_i in x_i by s_i (degree <= 2 in (u, s), so p_i has degree <= 4 in (X, y)).
Hence  2N gamma(X)^2 = min_y sum_i p_i / s_i^2  subject to the regions' g_i = 0, h_i >= 0.

The ratios' denominators s_i^2 vanish on camera i's principal plane, so the relaxation is posed on
the set where X is at least ``depth_min`` (world units) from every camera's principal plane, either
side (|s_i| >= depth_min ||P_i[2, :3]||), and within ``radius`` of the linear triangulation X0 of the
region centres (variables X = X0 + radius Z, ||Z|| <= 1, for O(1) data): there every s_i^2 is
certified positive, and the bound is a lower bound of gamma on that set only (not of gamma*); the
estimate's gamma is exact, as for every baseline.  Defaults: radius = 1 + ||X0||, depth_min =
``TPML_DEPTH_FRACTION`` * radius.

N_LMIVAR: the program of :func:`sospoly.minimize_ratios` -- one Gram matrix per view over all
3 + sum n_i variables, free w_i, Putinar multipliers of the region and depth constraints -- not
TPML's; the paper's counts (829 / 874 / 1259 at degree 4) are printed beside ours.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

import sospoly as sp
from sospoly.budget import as_budget

from .baselines import finish_baseline, prepare_baseline, start_baseline
from .result import Status, TriangulationResult

__all__ = ["TpmlResult", "tpml", "tpml_bound", "TPML_DEPTH_FRACTION", "TPML_RADIUS_FACTOR"]

#: default depth_min: this fraction of the radius (world units from each principal plane)
TPML_DEPTH_FRACTION = 0.02
#: default radius: this factor times (1 + ||X_start||)
TPML_RADIUS_FACTOR = 1.0


@dataclass(frozen=True)
class TpmlResult:
    """The baseline's estimate (``result``, a TriangulationResult without certificate) and the sum-of-ratios
    solve behind it (``ratios``): ``gamma_bound`` = sqrt(max(lower, 0) / (2N)) is a lower bound of gamma on
    the constrained set of the module docstring."""
    result: TriangulationResult
    ratios: object
    gamma_bound: float | None
    n_lmivar: int


def _homogenised(f: sp.Polynomial, u, s, world_gens) -> sp.Polynomial:
    """p = s^2 f(u / s, y): f over ("_u1", "_u2") + world gens, quadratic in the first two."""
    out = sp.Polynomial.constant(0.0, world_gens)
    for e, c in zip(f.exponents(), f.coefficients()):
        a, b = int(e[0]), int(e[1])
        if a + b > 2:
            raise ValueError("a region's f_i must be quadratic in the image point")
        mono = sp.Polynomial(world_gens, {tuple(int(t) for t in e[2:]): 1.0})
        out = out + float(c) * mono * u[0] ** a * u[1] ** b * s ** (2 - a - b)
    return out


def _problem(C, R, X0, depth_min, radius):
    """Ratios and constraints over Z (X = X0 + radius Z, ||Z|| <= 1: O(1) data) and the regions' y."""
    n_aux = [r.n_aux for r in R]
    gens = ("Z1", "Z2", "Z3") + tuple(f"y{i}_{k}" for i, n in enumerate(n_aux) for k in range(n))
    V = sp.variables(gens)
    X = [float(X0[k]) + radius * V[k] for k in range(3)] + [sp.Polynomial.constant(1.0, gens)]
    ext = ("_u1", "_u2") + gens
    U = sp.variables(ext)
    terms, eq, ineq, off = [], [], [], 3
    for i, (P, reg) in enumerate(zip(C, R)):
        u = [sum((float(P[r, k]) * X[k] for k in range(4)), sp.Polynomial.constant(0.0, gens)) for r in (0, 1)]
        s = sum((float(P[2, k]) * X[k] for k in range(4)), sp.Polynomial.constant(0.0, gens))
        y = U[2 + off: 2 + off + n_aux[i]]
        rp = reg.polynomials(U[:2], list(y))
        terms.append((_homogenised(rp.f.with_gens(ext), u, s, gens), s * s))
        for g in rp.eq:
            eq.append(_drop_u(g, ext, gens))
        for h in rp.ineq:
            ineq.append(_drop_u(h, ext, gens))
        floor = depth_min * float(np.linalg.norm(P[2, :3]))
        ineq.append(s * s - floor**2)              # |s_i| >= floor: q_i = s_i^2 certified positive
        off += n_aux[i]
    ineq.append(1.0 - V[0] ** 2 - V[1] ** 2 - V[2] ** 2)
    return terms, eq, ineq, gens


def _drop_u(p, ext, gens):
    if p.degree_in("_u1") > 0 or p.degree_in("_u2") > 0:
        raise ValueError("a region's constraints must not involve the image point")
    return sp.Polynomial(gens, {tuple(int(t) for t in e[2:]): float(c) for e, c in zip(p.exponents(),
                                                                                      p.coefficients())})


def tpml_bound(cameras, regions, degree: int = 4, *, depth_min: float | None = None, radius: float | None = None,
               budget=None) -> TpmlResult:
    """The world-domain sum-of-ratios relaxation (module docstring) at even ``degree``."""
    t0 = time.perf_counter()
    C, R = prepare_baseline(cameras, regions)
    if int(degree) != degree or degree < 4 or degree % 2:
        raise ValueError(f"degree must be an even integer >= 4, got {degree!r}")
    X0, err = start_baseline(C, R)
    if X0 is None:
        return TpmlResult(finish_baseline("tpml", None, C, R, t0, err, Status.ILL_POSED), None, None, 0)
    s0 = np.array([abs(float(P[2] @ np.append(X0, 1.0))) for P in C])
    if not np.all(s0 > 0):
        return TpmlResult(finish_baseline("tpml", None, C, R, t0, "the linear start lies on a camera's principal plane",
                                  Status.ILL_POSED), None, None, 0)
    radius = TPML_RADIUS_FACTOR * (1.0 + float(np.linalg.norm(X0))) if radius is None else float(radius)
    depth_min = TPML_DEPTH_FRACTION * radius if depth_min is None else float(depth_min)
    if not (depth_min > 0 and np.isfinite(depth_min) and radius > 0 and np.isfinite(radius)):
        raise ValueError(f"depth_min and radius must be positive and finite, got {depth_min!r}, {radius!r}")
    terms, eq, ineq, gens = _problem(C, R, X0, depth_min, radius)
    size = sp.sigma(len(gens), degree // 2)
    max_side = as_budget(budget).max_gram_side
    if size > max_side:
        msg = f"Gram side {size} exceeds the budget's max_gram_side {max_side}"
        return TpmlResult(finish_baseline("tpml", None, C, R, t0, msg, Status.BUDGET_EXCEEDED, delta=int(degree)), None,
                          None, 0)
    res = sp.minimize_ratios(terms, eq, ineq, degree=int(degree), gens=gens, budget=budget)
    bound = None if res.lower_bound is None else float(np.sqrt(max(res.lower_bound, 0.0) / (2 * len(C))))
    X = X0 + radius * res.minimizers[0][:3] if res.minimizers else None
    msg = (f"sum-of-ratios bound {res.lower_bound!r} (gamma >= {bound!r} for depths >= {depth_min:.3g}, "
           f"||X - X0|| <= {radius:.3g}); {res.status.value}")
    status = Status.NO_CERTIFICATE if X is not None else Status.SOLVER_FAILED
    out = finish_baseline("tpml", X, C, R, t0, msg, status, delta=int(degree), n_lmivar=res.n_lmivar)
    return TpmlResult(out, res, bound, res.n_lmivar)


def tpml(cameras, regions, degree: int = 4, **options) -> TriangulationResult:
    """The TPML-style baseline's estimate (no certificate; the bound is in the message and in
    :func:`tpml_bound`)."""
    return tpml_bound(cameras, regions, degree, **options).result
