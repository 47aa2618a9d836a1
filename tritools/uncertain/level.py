"""Outer bounds of the level set ``L(tau) = {X : gamma(X) <= tau}`` (docs/uncertainty.md, "The level set").

``gamma(X) <= tau`` implies ``d(Phi(X, P_i), R_i) <= sqrt(2N) tau`` in every view (gamma^2 is the mean
of the 2N squared coordinates of the distances), so L lies in the per-view set of the regions dilated
by ``sqrt(2N) tau``: its certified bounds (:func:`tritools.uncertainty`) are valid outer bounds of L,
up to sqrt(2N) loose.  Inner witnesses are points of L itself: for each side of the box a local
search (SLSQP, ``min +-X_k s.t. gamma(X)^2 <= tau^2``, from the local L2 optimum) whose result is
kept only if ``gamma(w) <= tau`` holds when re-evaluated; ``gap`` then measures the looseness of the
relaxation against them.  An SOS bound of L with the rigour of gamma_LB is not implemented.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..model.geometry import dlt, gamma, gamma_validated, refine_l2, validate_cameras
from ..model.regions import as_regions

__all__ = ["level_bounds"]


def _check_level(level) -> float:
    if isinstance(level, bool) or not isinstance(level, (int, float, np.integer, np.floating)) or \
            not np.isfinite(level) or level < 0:
        raise ValueError(f"level must be a finite number >= 0 (a bound tau on gamma, pixels), got {level!r}")
    return float(level)


def _start(C, regs, tau, estimate):
    """A point of L to start the local searches from: the estimate if it is in L, else the local L2
    optimum from the DLT of the region centres; None when neither is."""
    cands = [] if estimate is None else [np.asarray(estimate, float)]
    try:
        X0 = dlt(C, np.array([r.center for r in regs]))
        X1 = refine_l2(X0, C, regs)
        cands += [X for X in (X1, X0) if X is not None]
    except ValueError:
        pass
    for X in cands:
        if np.all(np.isfinite(X)) and float(gamma(X, C, regs)) <= tau:
            return X
    return None


def _g2_function(C, regs, start, scale):
    """``Y -> (gamma^2, gradient or None)`` at ``X = start + scale Y``: closed form with its gradient when
    every region is a Point (the usual level-set case), else :func:`gamma_validated` (gradient by
    finite differences)."""
    from ..model.regions import Point

    if all(isinstance(r, Point) for r in regs):
        xs = np.array([r.x for r in regs])
        n = 2 * len(regs)

        def f(Y):
            Xh = np.append(start + scale * Y, 1.0)
            h = C @ Xh
            u = h[:, :2] / h[:, 2:3]
            e = u - xs
            J = (C[:, :2, :3] - u[:, :, None] * C[:, 2:3, :3]) / h[:, 2:3, None]      # (N, 2, 3)
            return float(np.sum(e * e)) / n, 2.0 * scale * np.einsum("ij,ijk->k", e, J) / n
        return f
    return lambda Y: (float(gamma_validated((start + scale * Y)[None], C, regs)[0]) ** 2, None)


def _extreme(C, regs, tau, start, k, sign, scale):
    """A point of L found by SLSQP minimising ``sign * X_k`` (in coordinates (X - start) / scale), moved
    back towards ``start`` by the least step of a ladder that gives ``gamma <= tau`` (re-evaluated by
    :func:`gamma_validated`); or None."""
    from scipy.optimize import minimize

    f = _g2_function(C, regs, start, scale)
    t2 = max(tau * tau, 1e-300)
    con = {"type": "ineq", "fun": lambda Y: (tau * tau - f(Y)[0]) / t2}
    if f(np.zeros(3))[1] is not None:
        con["jac"] = lambda Y: -f(Y)[1] / t2
    try:
        with np.errstate(all="ignore"):
            res = minimize(lambda Y: sign * Y[k], np.zeros(3), jac=lambda Y: sign * np.eye(3)[k], method="SLSQP",
                           constraints=[con], options={"maxiter": 60, "ftol": 1e-10})
    except (ValueError, ArithmeticError):
        return None
    if not np.all(np.isfinite(res.x)):
        return None
    for theta in (1.0, 1 - 1e-9, 1 - 1e-6, 1 - 1e-4, 1 - 1e-2):
        X = start + scale * theta * res.x
        if float(gamma_validated(X[None], C, regs)[0]) <= tau:
            return X
    return None


def level_bounds(cameras, regions, level, estimate, opts):
    """:func:`tritools.uncertainty` with ``level=tau`` (module docstring)."""
    from .api import uncertainty

    tau = _check_level(level)
    if np.any(np.atleast_1d(np.asarray(opts.dilation, float)) != 0):
        raise ValueError("dilation must be 0 with level (the level set is defined by the regions as given)")
    C = validate_cameras(cameras, min_views=1, require_distinct=False)
    regs = as_regions(regions, len(C))
    r = float(np.sqrt(2 * len(C)) * tau) * (1 + 1e-12)
    out = uncertainty(C, regs, estimate=estimate, options=replace(opts, dilation=r, widen_roundoff=False))
    nan = np.full((3, 3), np.nan)
    start = _start(C, regs, tau, estimate) if out.status.value in ("bounded", "unbounded") else None
    wl, wh = nan.copy(), nan.copy()
    if start is not None:
        width = np.where(np.isfinite(out.hi - out.lo), out.hi - out.lo, 0.0)
        scale = float(np.max(width)) or 1.0
        for k in range(3):
            if np.isfinite(out.lo[k]):
                w = _extreme(C, regs, tau, start, k, 1.0, scale)
                wl[k] = np.nan if w is None else w
            if np.isfinite(out.hi[k]):
                w = _extreme(C, regs, tau, start, k, -1.0, scale)
                wh[k] = np.nan if w is None else w
    sides = [(wl[k, k] - out.lo[k]) for k in range(3) if np.isfinite(out.lo[k])] + \
            [(out.hi[k] - wh[k, k]) for k in range(3) if np.isfinite(out.hi[k])]
    gap = float(np.max(sides)) if sides else 0.0
    gap = np.inf if np.isnan(gap) else gap
    finite_width = np.max(out.hi - out.lo) if out.status.value == "bounded" else np.inf
    gap_rel = gap / finite_width if finite_width > 0 and np.isfinite(finite_width) else (np.inf if gap else 0.0)
    W = np.vstack([wl, wh])
    W = W[np.all(np.isfinite(W), axis=1)]
    if len(W):
        d = np.linalg.norm(W - out.estimate, axis=1)
        j = int(np.argmax(d))
        dw, inner = W[j].copy(), float(d[j])
    else:
        dw, inner = np.full(3, np.nan), np.nan
    return replace(out, witness_lo=wl, witness_hi=wh, gap=gap, gap_rel=gap_rel, distance_witness=dw,
                   distance_inner=inner, convexified=True, definition="level_relaxed")
