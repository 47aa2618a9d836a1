"""An in-front estimate where the certified one lies behind a camera and the regions admit other minimisers.

The L2 problem ignores cheirality (:func:`tritools.solve.decide.cheirality`).  With point regions its minimiser
is generically unique, so a certified estimate behind a camera is the answer.  With uncertain regions the
minimisers may form a set -- every X whose projections fall in all regions has gamma = 0 -- and the estimate the
certificate came with is one of them: it may lie behind the cameras while the set also holds points in front of
them (review 21b F1: two discs around a far point, the estimate at depth -1554, cost-0 points at depth +3210).
A verdict of ``behind_camera`` should then not be given, nor a COLMAP point dropped for it.

:func:`front_estimate` looks for such a point: on the ray of every view through its region's point nearest the
estimate's projection (of the first :data:`MAX_RAYS` views), at depths spanning 10^-3..10^9 times the camera
baseline (:data:`SWEEP`), the in-front sample of least gamma, refined by the local L2 refinement
(:func:`tritools.model.geometry.refine_l2`, kept where it stays in front).  It is only a candidate: the caller
decides the certificate again on it and keeps it only where the certificate holds there
(:func:`tritools.solve.stages.outcome.report_point`), so the rigour is the certificate's: the lower bound is
unchanged, the upper bound is gamma at the new point.
"""
from __future__ import annotations

import numpy as np

from ..model.cameras import depths_stack
from ..model.geometry import gamma_validated, refine_l2
from .report import point_report

__all__ = ["front_estimate", "SWEEP", "MAX_RAYS"]

#: depths of the ray samples in units of the camera baseline (the median distance between camera centres)
SWEEP = np.logspace(-3, 9, 49)
#: the rays of at most this many views are sampled (the cost stays bounded on long tracks)
MAX_RAYS = 8


def front_estimate(ctx, X: np.ndarray) -> np.ndarray | None:
    """The in-front candidate of least gamma found for ``ctx`` (a :class:`~tritools.solve.stages.context.
    PointContext`; a world point in front of every camera), or None (module docstring); point regions only: None.
    Only a candidate: the caller keeps it where its certificate holds there."""
    if all(r.is_point for r in ctx.regions) or X is None or not np.all(np.isfinite(X)):
        return None
    cams, regs, norm = ctx.cams_n, ctx.regs_n, ctx.norm
    best = _best_sample(ctx, cams, regs, norm.normalized_point(np.asarray(X, float)))
    if best is None:
        return None
    refined = refine_l2(best, cams, regs)
    for Yn in ((refined, best) if refined is not None else (best,)):
        W = norm.world_point(Yn)
        rep = point_report(W, ctx.cams, ctx.regions, ctx.opts.world_frame)
        if _in_front(rep) and rep.gamma is not None and np.isfinite(rep.gamma):
            return W
    return None


def _best_sample(ctx, cams: np.ndarray, regs: list, Xn: np.ndarray):
    """The in-front ray sample (normalised frame) of least gamma, or None."""
    centres, dirs = [], []
    for P, r in list(zip(cams, regs))[:MAX_RAYS]:
        M, p = P[:, :3], P[:, 3]
        try:
            c = -np.linalg.solve(M, p)
            h = P @ np.append(Xn, 1.0)
            u = h[:2] / h[2] if abs(h[2]) > 0 else np.asarray(r.center, float)
            d = np.linalg.solve(M, np.append(np.asarray(r.closest_point(u[None])[0], float), 1.0))
        except (np.linalg.LinAlgError, ValueError):
            continue
        if np.all(np.isfinite(c)) and np.all(np.isfinite(d)) and np.linalg.norm(d) > 0:
            centres.append(c)
            dirs.append(d / np.linalg.norm(d))
    if len(centres) < 1:
        return None
    C = np.array(centres)
    gaps = [np.linalg.norm(a - b) for k, a in enumerate(C) for b in C[k + 1:]]
    base = float(np.median(gaps)) if gaps and np.median(gaps) > 0 else 1.0
    t = np.concatenate([SWEEP, -SWEEP]) * base    # (the ray's sign toward positive depth is the depths' call)
    Y = (C[:, None, :] + t[None, :, None] * np.array(dirs)[:, None, :]).reshape(-1, 3)
    W = np.array([ctx.norm.world_point(y) for y in Y])
    with np.errstate(all="ignore"):
        dep = depths_stack(np.broadcast_to(ctx.cams, (len(W),) + ctx.cams.shape), W, ctx.opts.world_frame)
        front = np.all(np.isfinite(dep) & (dep > 0), axis=1)
        if not front.any():
            return None
        g = np.full(len(W), np.inf)
        g[front] = gamma_validated(W[front], ctx.cams, ctx.regions)     # one stacked evaluation of the samples
    k = int(np.argmin(g))
    return Y[k] if np.isfinite(g[k]) else None


def _in_front(rep) -> bool:
    return rep.depths is not None and bool(np.all(np.isfinite(rep.depths) & (rep.depths > 0)))
