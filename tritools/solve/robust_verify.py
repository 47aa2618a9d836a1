"""Verification of view subsets in the frame of their parent problem (the robust search's cheap sub-bounds).

A TLS search (:mod:`tritools.solve.robust`) needs certified lower bounds of L2*(S) = min_X sum_{i in S} d_i(X)^2
for many view subsets S of one point problem.  :func:`tritools.solve.fastpath.verify_points` on the
sub-problem normalises it afresh (DLT, then Levenberg-Marquardt from the DLT point to the tolerance 1e-13):
a fixed cost per subset that dominated the search.  Here the parent's normalisation is reused.

The frame.  The normalisation of the parent (:func:`tritools.model.normalize.normalization_stack`) maps the
image of view i by the similarity x' = s (x - x_i) (one scale s for every view) and the world by
X = X_0 + d X'; the normalised cameras P'_i reproduce it, Phi(X', P'_i) = s (Phi(X, P_i) - x_i).  A subset S of
the views, with the cameras P'_S and the observed points at the origin, is therefore the sub-problem of S in
normalised units: for every X,

    sum_{i in S} ||Phi(X', P'_i)||^2 = s^2 sum_{i in S} d_i(X)^2,      so   L2*(S) = L2'*(S) / s^2

exactly (SPEC §7; the same identity :func:`tritools.solve.fastpath.verify_checked` uses for the whole problem).
The degree-2 certificate (Corollary 1 at delta = 2, SPEC §7) of the normalised sub-problem,
:func:`tritools.solve.fastpath.lagrangian_bounds`, gives a rigorous lower bound c' <= L2'*(S) at any candidate v^
(the multipliers only propose; the bound comes from the polynomial data, with the margin of ``radius`` =
||v^||, which bounds every minimiser's norm since f(v*) = ||v*||^2 <= ||v^||^2).  Hence

    L2*(S) >= min(c', ||v^||^2) / s^2  (rounded down),

valid for any v^.  The candidate only decides how tight it is: X' is the best of the subset's DLT, the
parent's estimate and the cached estimates of S minus one view, polished by :data:`LM_STEPS` Levenberg-Marquardt
steps (a warm start converges in a few; view pairs not accepted get :data:`LM_MORE` more).  A bound is *accepted*
(stored as the subset's bound) where it meets the candidate's value under the certificate rule at the
sub-problem's own residual scale (the scale of the per-subset verification, ||v^||^2 / (s^2 |S|) pixels^2), or
where it is above the level at which the caller has no use for a larger one; the other subsets go on to the pair
packing bound / the batched SDP (:mod:`tritools.solve.robust_bounds`).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..model.normalize import normalization_stack
from ..model.stacked import damped_step, dlt_stack, next_damping, project_quiet, project_stack
from .fastpath import all_pairs_seconds, lagrangian_bounds

__all__ = ["ParentFrame", "parent_frames", "frames_of", "verify_in_parent", "LM_STEPS", "LM_MORE"]

#: subsets x views verified in one stacked call when a deadline is set (a 200-view track's leave-one-out subsets,
#: 40,000 view rows, polished for 0.3 s past a 1 s limit in one call; wave 9: a chunk of 4096 view pairs took ~60 ms,
#: the step by which a call could overrun its deadline, hence 1024)
CHUNK_VIEW_ROWS = 1024
#: before any chunk was timed, a subset of k views is predicted at this many times the all-pairs estimate
#: (:func:`tritools.solve.fastpath.all_pairs_seconds`: its bound, and a second one for pairs) plus
#: :data:`FIRST_SUBSET_SECONDS` (the polish and projections)
FIRST_SUBSET_FACTOR = 2.0
FIRST_SUBSET_SECONDS = 2e-4

#: damped Gauss-Newton steps polishing the start of each subset (a warm start rarely needs more than 3-4).
LM_STEPS = 6
#: further steps for the view pairs whose first bound was not accepted.
LM_MORE = 24
#: :func:`polish_rows` stops a row once a step changes its cost by at most this fraction of it.
POLISH_RTOL = 1e-13
#: a bound is rounded down by this factor (one division by s^2 on top of the certificate's own margin).
_ROUND_DOWN = 1.0 - 1e-12


@dataclass(frozen=True)
class ParentFrame:
    """The normalisation of one point problem (module docstring): normalised cameras (N, 3, 4), the parent's
    refined estimate Xn (3,) in the normalised world, the world frame (origin (3,), depth d) and the image scale
    s, with the coordinates' resolution (normalised units)."""
    cameras_n: np.ndarray
    Xn: np.ndarray
    origin: np.ndarray
    depth: float
    scale: float
    resolution: float

    def to_normalized(self, X: np.ndarray) -> np.ndarray:
        return (np.asarray(X, float) - self.origin) / self.depth

    def to_world(self, Xn: np.ndarray) -> np.ndarray:
        return self.origin + self.depth * Xn


def parent_frames(C: np.ndarray, x: np.ndarray) -> list:
    """The :class:`ParentFrame` of each of M point problems (C (M, N, 3, 4), x (M, N, 2)) from one
    :func:`tritools.model.normalize.normalization_stack` call; None where the normalisation failed."""
    return frames_of(normalization_stack(C, x))


def frames_of(st) -> list:
    """The :class:`ParentFrame` s of a :class:`tritools.model.normalize.NormalizationStack` (None where it failed)."""
    out = []
    for m in range(len(st.scale)):
        good = bool(st.ok[m]) and np.isfinite(st.scale[m]) and st.scale[m] > 0 and np.isfinite(st.depth[m])
        out.append(ParentFrame(st.cameras_n[m], st.Xn[m].copy(), st.origin[m].copy(), float(st.depth[m]),
                               float(st.scale[m]), float(st.resolution[m])) if good else None)
    return out


def _cost(Cn: np.ndarray, X: np.ndarray) -> np.ndarray:
    u, _, fin = project_stack(Cn, X)
    return np.where(fin, np.sum(u * u, axis=(1, 2)), np.inf)


def polish_rows(Cm: np.ndarray, X: np.ndarray, steps: int) -> np.ndarray:
    """At most ``steps`` Levenberg-Marquardt steps on sum_i ||Phi(X, P_i)||^2 for a stack of masked cameras
    Cm (M, N, 3, 4) (observations at the origin; masked views all zero), a step kept where it does not raise the cost;
    a row stops once a step moves its cost by at most POLISH_RTOL of it (each row on its own: a row's candidate does
    not depend on the other rows of its stack, so a problem gets the same numbers in any batch, review 19 F4).  Any
    candidate gives a valid bound: this only tightens it."""
    mu = np.full(len(X), 1e-3)
    active = np.ones(len(X), bool)
    with np.errstate(all="ignore"):
        absC2 = np.abs(Cm[:, :, 2, :])
        u, h, fin = project_quiet(Cm, X, absC2)
        cost = np.where(fin, np.sum(u * u, axis=(1, 2)), np.inf)
        for step_no in range(steps):
            den = np.where(h[..., 2] == 0, 1.0, h[..., 2])
            J = ((Cm[..., :2, :3] - u[..., None] * Cm[..., 2:3, :3]) / den[..., None, None]).reshape(len(X), -1, 3)
            r = u.reshape(len(X), -1)
            Jt = np.swapaxes(J, 1, 2)                      # (batched matmul: ~3x faster than einsum here)
            step = damped_step(Jt @ J, (Jt @ r[..., None])[..., 0], mu)
            Xt = X + np.where(np.isfinite(step), step, 0.0)
            ut, ht, fint = project_quiet(Cm, Xt, absC2)
            ct = np.where(fint, np.sum(ut * ut, axis=(1, 2)), np.inf)
            better = active & (ct <= cost)
            X = np.where(better[:, None], Xt, X)
            active &= ~(np.isfinite(cost) & (np.abs(ct - cost) <= POLISH_RTOL * cost))
            if not active.any() or step_no == steps - 1:    # (the last step: its state is not read again)
                break
            u, h = np.where(better[:, None, None], ut, u), np.where(better[:, None, None], ht, h)
            cost = np.where(better, ct, cost)
            mu = next_damping(mu, better)
    return X


def _starts(frames: list, subsets: list, Cn: np.ndarray, estimates: list) -> np.ndarray:
    """The best start (M, 3) per subset among its DLT, the parent's estimate and ``estimates`` (per subset, a list
    of world points, e.g. cached estimates of S minus one view), by the cost on the subset."""
    M, k = Cn.shape[:2]
    dlt, ok = dlt_stack(Cn, np.zeros((M, k, 2)))
    cands = [np.where(ok[:, None] & np.isfinite(dlt), dlt, 0.0), np.array([f.Xn for f in frames])]
    width = max((len(e) for e in estimates), default=0)
    for j in range(width):
        cands.append(np.array([f.to_normalized(e[j]) if j < len(e) else f.Xn
                               for f, e in zip(frames, estimates)]))
    costs = np.stack([_cost(Cn, X) for X in cands])
    best = np.argmin(np.where(np.isfinite(costs), costs, np.inf), axis=0)
    return np.stack(cands)[best, np.arange(M)]


def verify_in_parent(C: np.ndarray, frames: list, subsets: list, estimates: list, tolerances,
                     enough: np.ndarray | None = None, deadline=None) -> tuple:
    """Lower bounds (pixels^2) of L2*(S) for equal-size subsets S (sorted index arrays, one per problem) of the
    problems with raw cameras C (list of (N_m, 3, 4)) and :class:`ParentFrame` s ``frames`` (module docstring).

    Returns (accepted (M,) bool, bound (M,) pixels^2, X (M, 3) world estimates): a bound is accepted where it
    meets the candidate's value under the certificate rule at the subset's residual scale, or where it reaches
    ``enough`` (M,) (pixels^2: the level above which the caller has no use for a larger bound).  View pairs not
    accepted after :data:`LM_STEPS` steps get :data:`LM_MORE` more (large residuals converge slowly) and a second
    bound (measured in benchmarks/robust_speed.py: the second pass accepted 15 of 17 such pairs and 1 of 300
    larger subsets, so only pairs get it).  ``deadline`` (:class:`sospoly.budget.Deadline`): the all-pairs bound of
    a subset is not started where it would not fit (:func:`tritools.solve.fastpath.fits`; no bound there)."""
    M = len(subsets)
    if deadline is not None and deadline.expired:          # nothing accepted: the callers keep their valid bounds
        return np.zeros(M, bool), np.zeros(M), np.full((M, 3), np.nan)
    step = max(1, CHUNK_VIEW_ROWS // max(1, len(subsets[0])))
    if deadline is not None and M > min(step, max(1, _fitting(deadline, _first_cost(len(subsets[0])), M))):
        return _chunked(C, frames, subsets, estimates, tolerances, enough, deadline, step)   # deadline between
    return _verify(C, frames, subsets, estimates, tolerances, enough, deadline)


def _verify(C, frames, subsets, estimates, tolerances, enough, deadline) -> tuple:
    """:func:`verify_in_parent` of one stacked call."""
    M = len(subsets)
    Cn = np.stack([f.cameras_n[S] for f, S in zip(frames, subsets)])
    Craw = np.stack([c[S] for c, S in zip(C, subsets)])
    res = np.array([f.resolution for f in frames])
    s2 = np.array([f.scale for f in frames]) ** 2
    enough = np.full(M, np.inf) if enough is None else np.asarray(enough, float)
    Xn = polish_rows(Cn, _starts(frames, subsets, Cn, estimates), LM_STEPS)
    good, lb = _bounds(Craw, Cn, Xn, res, s2, enough, tolerances, deadline)
    again = np.nonzero(~good & np.isfinite(Xn).all(axis=1))[0]
    if again.size and len(subsets[0]) == 2:
        Xn[again] = polish_rows(Cn[again], Xn[again], LM_MORE)
        good[again], lb[again] = _bounds(Craw[again], Cn[again], Xn[again], res[again], s2[again], enough[again],
                                         tolerances, deadline)
    X = np.array([f.origin for f in frames]) + np.array([f.depth for f in frames])[:, None] * Xn
    return good, np.where(good, lb, 0.0), X


def _chunked(C, frames, subsets, estimates, tolerances, enough, deadline, step: int) -> tuple:
    """:func:`verify_in_parent` in chunks of at most ``step`` subsets, each of as many subsets as are predicted to end
    before the deadline at the wall time per subset of the chunks before (equal-size subsets cost alike); the first
    chunk at :func:`_first_cost` per subset, at least one subset: a chunk of large subsets (banded bounds of 400 views)
    takes ~0.1-0.5 s, and one of 34 subsets of 29 views (1024 view rows, all pairs) ~0.1 s, which a call would
    otherwise overrun its limit by (review 15 F1).  The subsets not reached are not accepted (bound 0, no
    estimate)."""
    M = len(subsets)
    good, lb, X = np.zeros(M, bool), np.zeros(M), np.full((M, 3), np.nan)
    per_subset = _first_cost(len(subsets[0]))      # predicted until a chunk is timed, then the largest measured
    k = 0
    while k < M:
        fit = _fitting(deadline, per_subset, M - k)  # as many as are predicted to end in time; the first chunk
        stop = k + min(step, fit if k else max(1, fit))   # at least one subset (its prediction is only an estimate)
        if stop == k:
            break
        t = time.monotonic()
        good[k:stop], lb[k:stop], X[k:stop] = _verify(
            C[k:stop], frames[k:stop], subsets[k:stop], estimates[k:stop], tolerances,
            None if enough is None else np.asarray(enough)[k:stop], deadline)
        per_subset = max(per_subset if k else 0.0, (time.monotonic() - t) / (stop - k))
        k = stop
    return good, lb, X


def _first_cost(k: int) -> float:
    """The predicted seconds of one subset of ``k`` views before any was timed (:data:`FIRST_SUBSET_FACTOR`)."""
    return FIRST_SUBSET_FACTOR * all_pairs_seconds(k) + FIRST_SUBSET_SECONDS


def _fitting(deadline, per_subset: float, most: int) -> int:
    """How many subsets (at most ``most``) at ``per_subset`` seconds end before ``deadline``; ``most`` without a
    limit, 0 once it has passed."""
    remaining = deadline.remaining()
    if remaining is None:
        return most
    if remaining <= 0.0:
        return 0
    return int(min(most, remaining // per_subset)) if per_subset > 0 else most


def _bounds(Craw, Cn, Xn, res, s2, enough, tolerances, deadline=None) -> tuple:
    """(accepted, bound in pixels^2) of :func:`verify_in_parent` at the normalised candidates Xn."""
    M, k = Cn.shape[:2]
    u, _, fin = project_stack(Cn, Xn)
    fin &= np.isfinite(Xn).all(axis=1)
    v = np.where(fin[:, None], u.reshape(M, -1), 0.0)
    radius = np.sqrt(np.sum(v * v, axis=1))
    lower, upper, ok = lagrangian_bounds(Craw, Cn, v, fin.copy(), radius, res, tolerances, deadline=deadline)
    with np.errstate(invalid="ignore", over="ignore"):
        lb = np.maximum(np.minimum(lower, upper), 0.0) / s2 * _ROUND_DOWN
        ub = upper / s2
        good = ok & fin & np.isfinite(lb) & np.isfinite(ub)
        good &= np.asarray(tolerances.certified(lb, ub, ub / k), bool) | (lb >= enough)
    return good, np.where(good, lb, 0.0)
