"""Outer bounds of the level set ``L(tau) = {X : gamma(X) <= tau, depth_i(X) >= 0 for every i}``
(docs/uncertainty.md, "The level set"): the points in front of every camera, as in the per-view set.
gamma itself -- and the certificate of :func:`tritools.triangulate` -- ignores cheirality, so an L2 optimum
behind a camera (``TriangulationResult.in_front`` False) is not a point of L; ``empty`` then says that no
point in front of every camera reaches the level (review 23a F1).

``gamma(X) <= tau`` implies ``d(Phi(X, P_i), R_i) <= sqrt(2N) tau`` in every view (gamma^2 is the mean
of the 2N squared coordinates of the distances), so L lies in the per-view set of the regions dilated
by ``sqrt(2N) tau``: its certified bounds (:func:`tritools.uncertainty`) are valid outer bounds of L,
up to sqrt(2N) loose.  Inner witnesses are points of L itself: for each side of the box a local
search (SLSQP, ``min +-X_k s.t. gamma(X)^2 <= tau^2`` and every depth >= 0, from a point of L) whose
result is kept only if ``gamma(w) <= tau`` and its depths (:func:`tritools.depths`, the options'
``world_frame``) hold when re-evaluated; ``gap`` then measures the looseness of the bounds against them.
For point regions the box is tightened by certified SOS bounds (:func:`_sos_box`, ``sospoly.minimize`` with
a radius: the rigour of gamma_LB; its programs ignore the depths, so they bound a superset of L within the
relaxation's box).
"""
from __future__ import annotations

from dataclasses import replace
from fractions import Fraction

import numpy as np

from ..model.geometry import depths, dlt, gamma_validated, refine_l2, validate_cameras
from ..model.cameras import as_world_frame, depth_rows
from ..model.regions import as_regions
from .witness import in_box, witness_gap

__all__ = ["level_bounds"]


def _check_level(level) -> float:
    if isinstance(level, bool) or not isinstance(level, (int, float, np.integer, np.floating)) or \
            not np.isfinite(level) or level < 0:
        raise ValueError(f"level must be a finite number >= 0 (a bound tau on gamma, pixels), got {level!r}")
    return float(level)


def _in_front(C, X, frame) -> bool:
    """Every depth of X (:func:`tritools.depths` in ``frame``) is >= 0 (the closure of "in front")."""
    with np.errstate(all="ignore"):
        return bool(np.all(depths(X, C, frame) >= 0))


def _in_level(C, regs, tau, X, frame) -> bool:
    """X is a point of L: finite, gamma(X) <= tau (:func:`gamma_validated`) and in front of every camera."""
    return bool(np.all(np.isfinite(X))) and float(gamma_validated(np.asarray(X, float)[None], C, regs)[0]) <= tau \
        and _in_front(C, X, frame)


def _start(C, regs, tau, estimate, frame):
    """A point of L to start the local searches from: the estimate if it is in L, else the local L2
    optimum from the DLT of the region centres, else the DLT point; None when none is."""
    cands = [] if estimate is None else [np.asarray(estimate, float)]
    try:
        X0 = dlt(C, np.array([r.center for r in regs]))
        X1 = refine_l2(X0, C, regs)
        cands += [X for X in (X1, X0) if X is not None]
    except ValueError:
        pass
    for X in cands:
        if _in_level(C, regs, tau, X, frame):
            return X
    return None


def _g2_function(C, regs, start, scale):
    """``Y -> (gamma^2, gradient or None)`` at ``X = start + scale Y``: closed form with its gradient when
    every region is a single point (``is_point``, the usual level-set case), else :func:`gamma_validated`
    (gradient by finite differences)."""
    if all(r.is_point for r in regs):
        xs = np.array([r.center for r in regs])
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


def _extreme(C, regs, tau, start, k, sign, scale, frame):
    """A point of L found by SLSQP minimising ``sign * X_k`` (in coordinates (X - start) / scale) with every
    depth >= 0, moved back towards ``start`` by the least step of a ladder that gives a point of L
    (:func:`_in_level`: gamma re-evaluated by :func:`gamma_validated`, the depths by :func:`tritools.depths`;
    L is star-shaped about no point in general, so the ladder only trims the solver's last step); or None."""
    from scipy.optimize import minimize

    f = _g2_function(C, regs, start, scale)
    t2 = max(tau * tau, 1e-300)
    con = {"type": "ineq", "fun": lambda Y: (tau * tau - f(Y)[0]) / t2}
    if f(np.zeros(3))[1] is not None:
        con["jac"] = lambda Y: -f(Y)[1] / t2
    rows = depth_rows(np.asarray(C, float)) * as_world_frame(frame).sign            # depth_i = rows_i . X~
    d0 = rows[:, :3] @ start + rows[:, 3]
    dscale = np.maximum(np.abs(d0), 1e-300)
    front = {"type": "ineq", "fun": lambda Y: (d0 + scale * (rows[:, :3] @ Y)) / dscale,
             "jac": lambda Y: scale * rows[:, :3] / dscale[:, None]}
    try:
        with np.errstate(all="ignore"):
            res = minimize(lambda Y: sign * Y[k], np.zeros(3), jac=lambda Y: sign * np.eye(3)[k], method="SLSQP",
                           constraints=[con, front], options={"maxiter": 60, "ftol": 1e-10})
    except (ValueError, ArithmeticError):
        return None
    if not np.all(np.isfinite(res.x)):
        return None
    for theta in (1.0, 1 - 1e-9, 1 - 1e-6, 1 - 1e-4, 1 - 1e-2):
        X = start + scale * theta * res.x
        if _in_level(C, regs, tau, X, frame):
            return X
    return None


def _projection_equation(P, j, x, c, s, w, u, weight):
    """``weight ((x + w) h_3 - h_j)`` with ``h_r = P_r . (c + s u, 1)``, its coefficients computed exactly from the
    float data (rational arithmetic, one rounding each): in a georeferenced world the constant term ``x P_3 . c~ -
    P_j . c~`` is a difference of terms ~1e10 times larger, whose float rounding moved the set the SOS bounds
    certified (review 43a: points of the level set up to 5e-4 of the box width outside it)."""
    F = [Fraction(float(v)) for v in c] + [Fraction(1)]
    xr = Fraction(x)
    lin = [xr * Fraction(float(P[2, k])) - Fraction(float(P[j, k])) for k in range(4)]
    const = float(sum(lin[k] * F[k] for k in range(4)) * Fraction(weight))
    a3 = float(sum(Fraction(float(P[2, k])) * F[k] for k in range(4)) * Fraction(weight))
    poly = const + a3 * w
    for k in range(3):
        poly = poly + float(lin[k] * Fraction(float(s[k])) * Fraction(weight)) * u[k] \
            + float(Fraction(float(P[2, k])) * Fraction(float(s[k])) * Fraction(weight)) * (w * u[k])
    return poly


def _sos_box(C, regs, tau, lo, hi, degree, time_limit=None):
    """Tighter bounds of L for point regions through sospoly: with ``X = c + s u`` (the relaxation's box,
    ``|u_k| <= 1``) and ``x_i = x^_i + sqrt(2N) tau v_i`` (``sum ||v_i||^2 <= 1`` is ``gamma <= tau``),
    ``min +-u_k`` subject to the projection equalities ``x_i (p3_i . X~) = p12_i . X~`` (each row
    scaled) is a polynomial program whose certified lower bound (``sospoly.minimize`` at ``degree``,
    rigorous with ``radius = 2``: ``||(u, v)|| <= 2`` on the feasible set) bounds ``X_k``.  Returns
    (lo, hi) intersected with the box, or None if a program gives no bound or ``time_limit`` seconds (for the six
    programs together; None: none) pass first."""
    import time

    import sospoly

    from .rigour import round_down, round_up

    start = time.monotonic()
    N = len(C)
    xs = np.array([r.center for r in regs])
    c, s = lo / 2.0 + hi / 2.0, hi / 2.0 - lo / 2.0
    tp = float(np.sqrt(2 * N) * tau)
    V = sospoly.variables(" ".join([f"u{k}" for k in range(3)] + [f"v{i}_{j}" for i in range(N) for j in range(2)]))
    u, v = V[:3], [V[3 + 2 * i:5 + 2 * i] for i in range(N)]
    eqs = []
    for i, P in enumerate(C):
        for j in range(2):
            scale = float(np.abs(P[j, :3]) @ np.abs(s) + abs(xs[i, j]) * (np.abs(P[2, :3]) @ np.abs(s)))
            eqs.append(_projection_equation(P, j, float(xs[i, j]), c, s, tp * v[i][j], u, 1.0 / max(scale, 1e-300)))
    ineq = [1 - sum(w[0] ** 2 + w[1] ** 2 for w in v)] + [1 - u[k] ** 2 for k in range(3)]
    new_lo, new_hi = lo.copy(), hi.copy()
    for k in range(3):
        for sign in (1.0, -1.0):
            left = None if time_limit is None else time_limit - (time.monotonic() - start)
            if left is not None and left <= 0:
                return None
            res = sospoly.minimize(sign * u[k], eq=eqs, ineq=ineq, degree=degree, radius=2.0, refine=False,
                                   budget=sospoly.Budget(time_limit=left))
            if res.lower_bound is None or not np.isfinite(res.lower_bound):
                return None
            if sign > 0:
                new_lo[k] = max(lo[k], float(round_down(c[k] + s[k] * res.lower_bound)))
            else:
                new_hi[k] = min(hi[k], float(round_up(c[k] - s[k] * res.lower_bound)))
    return new_lo, new_hi


def level_bounds(cameras, regions, level, estimate, opts):
    """:func:`tritools.uncertainty` with ``level=tau`` (module docstring)."""
    from .api import DILATION_MAX, uncertainty

    tau = _check_level(level)
    if np.any(np.atleast_1d(np.asarray(opts.dilation, float)) != 0):
        raise ValueError("dilation must be 0 with level (the level set is defined by the regions as given)")
    C = validate_cameras(cameras, min_views=1, require_distinct=False)
    regs = as_regions(regions, len(C))
    r = float(np.sqrt(2 * len(C)) * tau) * (1 + 1e-12)
    if r > DILATION_MAX:
        raise ValueError(f"level must be at most {DILATION_MAX / np.sqrt(2 * len(C)):g} pixels for {len(C)} views "
                         f"(the dilation sqrt(2N) level must stay below {DILATION_MAX:g}), got {level!r}")
    # widening by the projections' round-off only enlarges the set (still an outer bound): a level far below
    # the round-off must not report exact data's level set (which holds the true point) empty
    out = uncertainty(C, regs, estimate=estimate, options=replace(opts, dilation=r))
    definition = "level_relaxed"
    if opts.level_degree and out.status.value == "bounded" and all(g.is_point for g in regs):
        box = _sos_box(C, regs, tau, out.lo, out.hi, opts.level_degree, opts.level_time_limit)
        if box is not None:
            out = _with_box(out, *box)
            definition = "level_sos"
    nan = np.full((3, 3), np.nan)
    frame = opts.world_frame
    start = _start(C, regs, tau, estimate, frame) if out.status.value in ("bounded", "unbounded") else None
    wl, wh = nan.copy(), nan.copy()
    if start is not None:
        width = np.where(np.isfinite(out.hi - out.lo), out.hi - out.lo, 0.0)
        scale = float(np.max(width)) or 1.0
        for k in range(3):
            if np.isfinite(out.lo[k]):
                w = _extreme(C, regs, tau, start, k, 1.0, scale, frame)
                wl[k] = np.nan if w is None else w
            if np.isfinite(out.hi[k]):
                w = _extreme(C, regs, tau, start, k, -1.0, scale, frame)
                wh[k] = np.nan if w is None else w
    wl, wh = in_box(wl, out.lo, out.hi), in_box(wh, out.lo, out.hi)
    gap, gap_rel, inner, dw = witness_gap(out.lo, out.hi, wl, wh, out.estimate, out.status.value == "bounded")
    return replace(out, witness_lo=wl, witness_hi=wh, gap=gap, gap_rel=gap_rel, distance_witness=dw,
                   distance_inner=inner, convexified=definition == "level_relaxed", definition=definition)


def _with_box(out, lo, hi):
    """The result with a tighter box: the distance bound from its farthest corner (rounded up)."""
    from .rigour import round_up

    far = np.maximum(np.abs(lo - out.estimate), np.abs(hi - out.estimate))
    dist = float(round_up(np.sqrt(np.sum(far * far)) * (1 + 1e-15)))
    return replace(out, lo=lo, hi=hi, max_distance=min(out.max_distance, dist))
