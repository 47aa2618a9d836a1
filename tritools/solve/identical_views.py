"""Views listed more than once: k copies of a view are one view of weight k (the same cost function).

Two views i, j are *the same view* when their cameras are proportional, ``P_j = lambda P_i`` with
``lambda = +-2^m`` -- exactly, entry by entry (the same projection Phi(X, P) of the paper's eq. (1), and the same
depth: Hartley & Zisserman eq. (6.15) is invariant to ``lambda``) -- their regions are equal, and, with ``robust=``,
so are their thresholds.  A copy rescaled by 3.0 in floats is another camera to round-off and is not merged: in a
georeferenced frame that round-off moves projections by far more than it seems (review 35b: cameras 20 um apart
along the axis 4e6 from the origin differed by 64 ulps of their norm, and merging them raised gamma_LB 8 % above
the optimum).

k copies of view i add ``k d_i(X)^2`` to the L2 cost f(X) = 2N gamma(X)^2 (paper eq. (6)) and
``k min(d_i^2, c_i^2) = min((sqrt(k) d_i)^2, (sqrt(k) c_i)^2)`` to the TLS cost, so they are one view whose image
is scaled by ``sqrt(k)`` about its origin: camera ``diag(sqrt(k), sqrt(k), 1) P_i`` (stored as the projectively
equal ``diag(1, 1, 1/sqrt(k)) P_i``), region
``R_i.similarity(sqrt(k), 0)``, threshold ``sqrt(k) c_i`` (:meth:`ViewMerge.reduce`).  f is the same function
of X, so the N' < N views' problem has the same minimisers and

    gamma = gamma' sqrt(N' / N)

(:meth:`ViewMerge.expand`: the bounds scaled with outward rounding, per-view fields mapped back, every view
of a group its copy's residual / sqrt(k), depth and inlier flag).  The scaling by sqrt(k) rounds the copy's camera
and region: a projection moves by about eps K |x| pixels, K the cancellation of its denominator (the largest
sum_j |P_3j| |X~_j| / |P_3 X~| at the DLT point of the region centres, ~1 near the cameras, ~1e6 for a scene 5 m
across 4e6 from the origin).  So views are merged only while K <= :data:`MAX_CANCELLATION` (not in a georeferenced
frame: review 35b M1 saw gamma_LB 8e-7 above the optimum there), and gamma_LB is lowered by the rounding's effect
at that point (:attr:`ViewMerge.margin`, :func:`_rounding`).

Why it matters: the degree plan's size rules count views (six views with one listed twice lost the certificate
where the five distinct views are certified, review 34a M1), and a TLS search enumerates inlier sets of copies that
can only be in or out together (34a M3).
"""
from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass

import numpy as np

from ..result import Attempt, TriangulationResult

__all__ = ["ViewMerge", "identical_views", "may_repeat_views", "MAX_CANCELLATION"]

#: views are merged only where the projection's cancellation K at the DLT point is at most this (module docstring)
MAX_CANCELLATION = 1e3
#: ... and where no merged view's region is an ellipse of a larger eigenvalue ratio (:func:`_thin_ellipse`)
MAX_MERGED_ELLIPSE_RATIO = 1e4
#: a fixed direction for the one-number sort key of a camera (any generic vector).
_KEY = np.sin(np.arange(1.0, 13.0) * 1.618)
#: keys (:func:`_keys`, in [0, |_KEY|^2 < 7]) this close are compared in full (exact copies give equal keys; the
#: margin covers a matrix product's rounding differing between rows)
_KEY_TOL = 4096 * np.finfo(float).eps
_UP, _DOWN = 1.0 + 4 * np.finfo(float).eps, 1.0 - 4 * np.finfo(float).eps


@dataclass(frozen=True)
class ViewMerge:
    """The reduction of a view list with copies: ``group[i]`` the reduced view of view i, ``keep[g]`` the first
    view of group g, ``counts[g]`` its number of copies (module docstring)."""
    group: np.ndarray
    keep: np.ndarray
    counts: np.ndarray
    margin: float = 0.0           # pixels: gamma_LB is lowered by this (the scaling's round-off, module docstring)

    @property
    def ratio(self) -> float:
        """sqrt(N' / N): gamma of the caller's views = ratio * gamma of the reduced ones."""
        return float(np.sqrt(len(self.keep) / len(self.group)))

    def reduce(self, cameras: np.ndarray, regions, thresholds=None) -> tuple | None:
        """(cameras (N', 3, 4), regions, thresholds or None) of the reduced problem; None where scaling a region
        by sqrt(k) leaves the floats (the caller then solves the views as given).  The camera's third row is
        divided by sqrt(k) (projectively diag(sqrt(k), sqrt(k), 1) P: nothing overflows)."""
        root = np.sqrt(self.counts.astype(float))
        C = np.array(cameras[self.keep], float)
        C[:, 2, :] /= root[:, None]
        try:
            with np.errstate(all="ignore"):
                regs = [regions[i] if k == 1 else regions[i].similarity(r, (0.0, 0.0))
                        for i, k, r in zip(self.keep, self.counts, root)]
        except (ValueError, ArithmeticError):        # a region at ~1e308 scaled past the largest float
            return None
        c = None if thresholds is None else np.asarray(thresholds, float)[self.keep] * root
        return C, regs, c

    def options(self, opts):
        """``opts`` with ``lower_bound_stop`` (a level of gamma) in the reduced problem's gamma."""
        stop = opts.lower_bound_stop
        return opts if stop is None else opts.replace(lower_bound_stop=stop / self.ratio)

    def expand(self, res: TriangulationResult) -> TriangulationResult:
        """The reduced problem's result for the caller's N views (module docstring)."""
        r, g = self.ratio, self.group
        root = np.sqrt(self.counts.astype(float))[g]
        fields = {name: _scaled(getattr(res, name), r, up) for name, up in
                  (("gamma_lb", False), ("gamma_ub", True), ("gamma_ub_raw", True))}
        if fields["gamma_lb"] is not None and self.margin > 0:
            fields["gamma_lb"] = max(0.0, fields["gamma_lb"] - self.margin)
        if res.image_points is not None:
            fields["image_points"] = res.image_points[g] / root[:, None]
        if res.residuals is not None:
            fields["residuals"] = res.residuals[g] / root
        for name in ("depths", "inliers"):
            if getattr(res, name) is not None:
                fields[name] = getattr(res, name)[g]
        fields["attempts"] = tuple(_attempt(a, r, self.margin) for a in res.attempts)
        message = res.message
        if res.inliers is not None:             # the TLS count of the caller's views, not the reduced ones
            message = re.sub(r"^TLS: \d+/\d+ inliers", f"TLS: {int(fields['inliers'].sum())}/{len(g)} inliers", message)
        fields["message"] = (message + "; " if message else "") + self.describe()
        return dataclasses.replace(res, **fields)

    def describe(self) -> str:
        """One line naming the copies, e.g. ``views 3, 5 repeat view 0: solved as 4 views (copies weighted, exact)``."""
        parts = []
        for gi, first in enumerate(self.keep):
            if self.counts[gi] > 1:
                copies = [int(i) for i in np.flatnonzero(self.group == gi) if i != first]
                parts.append(f"view{'s' if len(copies) > 1 else ''} {', '.join(map(str, copies))} "
                             f"repeat{'' if len(copies) > 1 else 's'} view {int(first)}")
        return f"{'; '.join(parts)}: solved as {len(self.keep)} views (copies weighted, exact)"


def _scaled(value, r: float, up: bool):
    """``value * r`` rounded outward (up for an upper bound, down for a lower bound); None stays None."""
    if value is None or not np.isfinite(value):
        return value
    out = float(value) * r
    return out * (_UP if up else _DOWN) if out > 0 else out


def _attempt(a, r: float, margin: float):
    if not isinstance(a, Attempt):
        return a
    lb = _scaled(a.gamma_lb, r, False)
    lb = lb if lb is None or margin <= 0 else max(0.0, lb - margin)
    return dataclasses.replace(a, gamma_lb=lb, gamma_ub=_scaled(a.gamma_ub, r, True))


def identical_views(cameras: np.ndarray, regions, thresholds=None) -> ViewMerge | None:
    """The :class:`ViewMerge` of validated cameras (N, 3, 4) and regions (and thresholds), or None when no view
    repeats another or merging would leave fewer than two views.  Cost: a sort of one number per camera; views
    are compared in full only where those numbers meet."""
    N = len(cameras)
    if N < 3:
        return None
    A = np.asarray(cameras, float).reshape(N, 12)
    key = _keys(A)
    ks = sorted(key.tolist())
    if min(b - a for a, b in zip(ks, ks[1:])) > _KEY_TOL:      # the common case: no camera near another
        return None
    order = np.argsort(key, kind="stable")
    rep = np.arange(N)
    for run in _runs(key[order]):                # views whose keys chain within _KEY_TOL: compared pairwise
        roots: list = []
        for j in order[run]:
            root = next((r for r in roots if _same(A, regions, thresholds, r, j)), None)
            if root is None:
                roots.append(j)              # (one camera seeing two keypoints: two roots of one run)
            else:
                rep[j] = root
    if np.all(rep == np.arange(N)):
        return None
    firsts = np.array([min(np.flatnonzero(rep == r)) for r in rep])     # each group named by its first view
    keep, group, counts = np.unique(firsts, return_inverse=True, return_counts=True)
    if len(keep) < 2:
        return None
    K, margin = _rounding(A.reshape(N, 3, 4), regions, float(np.sqrt(counts.max())))
    if not K <= MAX_CANCELLATION or any(_thin_ellipse(regions, int(i)) for i, k in zip(keep, counts) if k > 1):
        return None
    return ViewMerge(group.astype(int), keep.astype(int), counts.astype(int), margin)


def _rounding(C: np.ndarray, regions, root: float) -> tuple[float, float]:
    """(K, margin) at the DLT point X0 of the region centres (computed in the cameras' world frame,
    :func:`tritools.model.frame.world_frame`, and moved back): K = max_i sum_j |P_i3j| |X0~_j| / |P_i3 X0~|, the
    cancellation of the projection's denominator (inf where X0 is not finite or on a principal plane), and the margin
    in pixels, 4 eps (K_xy + K M + sqrt(k) M) with K_xy = max_i,r<3 sum_j |P_irj| |X0~_j| / |P_i3 X0~| (pixels) and
    M = max|x| + 1 over the centres: what one rounding of a copy's camera row and region moves a distance by."""
    from ..model.frame import world_frame
    from ..model.stacked import dlt_stack

    try:
        x = np.asarray(regions, float) if isinstance(regions, np.ndarray) else np.array([r.center for r in regions])
        with np.errstate(all="ignore"):
            frame = world_frame(C)          # the DLT in the cameras' own frame: in the caller's, a georeferenced
            X0, ok = dlt_stack(frame.cameras(C)[None], x[None])     # world's cancellation moved it by 3e6 (review 43a)
            Xh = np.append(frame.user_point(X0[0]), 1.0)
            den = np.abs(C[:, 2, :] @ Xh)
            terms = (np.abs(C) @ np.abs(Xh)) / den[:, None]
            K, K_xy, M = float(terms[:, 2].max()), float(terms[:, :2].max()), float(np.max(np.abs(x))) + 1.0
            margin = 4 * np.finfo(float).eps * (K_xy + K * M + root * M)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError):
        return np.inf, np.inf
    if not (bool(ok[0]) and np.isfinite(margin)):
        return np.inf, np.inf
    return K, margin


def _thin_ellipse(regions, i: int) -> bool:
    """Whether view i's region is an ellipse (its conic form, asked of the region) with an eigenvalue ratio above
    :data:`MAX_MERGED_ELLIPSE_RATIO`: scaling it by sqrt(k) rounds s^2 D entry by entry, which moves its border by up
    to ~eps lam_max / sqrt(lam_min) (review 43c: a 3666 x 0.0047 px ellipse listed twice, its merged copy's minor
    axis 1.2e-5 thinner, both bounds certified 3e-4 above the optimum); such views are not merged."""
    if isinstance(regions, np.ndarray):
        return False
    from ..model.regions import ConeKind, conic_form_of
    from ..model.regions.shapes import shape_fields

    try:
        form = conic_form_of(regions[i])
    except (TypeError, ValueError, AttributeError, NotImplementedError):
        return True                              # (unknown: not merged)
    if form.kind != ConeKind.ELLIPSE:
        return False
    lam = shape_fields(np.asarray(form.D, float)[None])[4][0]
    return not lam[1] <= MAX_MERGED_ELLIPSE_RATIO * lam[0]


def _runs(sorted_keys: np.ndarray) -> list:
    """Slices of the sorted keys whose neighbours lie within _KEY_TOL of each other (runs of two or more)."""
    cut = np.flatnonzero(np.diff(sorted_keys) > _KEY_TOL) + 1
    bounds = np.concatenate([[0], cut, [len(sorted_keys)]])
    return [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:]) if b - a > 1]


def may_repeat_views(C: np.ndarray) -> np.ndarray:
    """The vectorised filter of :func:`identical_views` for a stack of cameras (M, N, 3, 4): False where no camera of
    problem m is near another (then ``identical_views`` of that problem is None), True where it must be asked."""
    M, N = C.shape[:2]
    if N < 3 or M == 0:
        return np.zeros(M, bool)
    key = np.sort(_keys(np.asarray(C, float).reshape(M * N, 12)).reshape(M, N), axis=1)
    return np.any(np.diff(key, axis=1) <= _KEY_TOL, axis=1)


def _keys(A: np.ndarray) -> np.ndarray:
    """One number per camera (row of A (n, 12)), the same for every nonzero multiple of it: (a.v)^2 / |a|^2 for a
    fixed generic v (rows of moderate magnitude as they are; others divided by their largest magnitude first, so
    nothing over- or underflows).  A filter: copies equal up to round-off give numbers within _KEY_TOL."""
    if np.abs(A).max() < 1e150:
        n2 = np.einsum("ij,ij->i", A, A)
        if n2.min() > 1e-280:
            return (A @ _KEY) ** 2 / n2
    B = A / np.abs(A).max(axis=1)[:, None]
    return (B @ _KEY) ** 2 / np.einsum("ij,ij->i", B, B)


def _same(A: np.ndarray, regions, thresholds, i: int, j: int) -> bool:
    """Views i and j are the same view (module docstring): A (N, 12) the cameras, P_j = +-2^m P_i exactly."""
    k = int(np.argmax(np.abs(A[i])))
    lam = A[j, k] / A[i, k]
    mant, _ = np.frexp(lam)
    if abs(mant) != 0.5 or not np.array_equal(A[i] * lam, A[j]):
        return False
    if thresholds is not None and not (thresholds[i] == thresholds[j]):
        return False
    if isinstance(regions, np.ndarray):                 # observed points (N, 2)
        return bool(np.array_equal(regions[i], regions[j]))
    return regions[i] == regions[j]
