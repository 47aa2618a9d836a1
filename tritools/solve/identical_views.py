"""Views listed more than once: k copies of a view are one view of weight k (an exact reduction).

Two views i, j are *the same view* when their cameras are proportional, ``P_j = lambda P_i`` with
``lambda != 0`` (the same projection Phi(X, P) of the paper's eq. (1), and the same depth: Hartley & Zisserman
eq. (6.15) is invariant to ``lambda``), their regions are equal, and -- with ``robust=`` -- so are their
thresholds.  Cameras are compared after scaling each to unit Frobenius norm, up to :data:`SAME_CAMERA_TOL`
(round-off: a copy rescaled by 3.0 in floats is the same view).

k copies of view i add ``k d_i(X)^2`` to the L2 cost f(X) = 2N gamma(X)^2 (paper eq. (6)) and
``k min(d_i^2, c_i^2) = min((sqrt(k) d_i)^2, (sqrt(k) c_i)^2)`` to the TLS cost, so they are one view whose image
is scaled by ``sqrt(k)`` about its origin: camera ``diag(sqrt(k), sqrt(k), 1) P_i`` (stored as the projectively
equal ``diag(1, 1, 1/sqrt(k)) P_i``), region
``R_i.similarity(sqrt(k), 0)``, threshold ``sqrt(k) c_i`` (:meth:`ViewMerge.reduce`).  f is the same function
of X, so the N' < N views' problem has the same minimisers and

    gamma = gamma' sqrt(N' / N)

(:meth:`ViewMerge.expand`: the bounds scaled with outward rounding, per-view fields mapped back, every view
of a group its copy's residual / sqrt(k), depth and inlier flag).  Why it matters: the degree plan's size rules
count views (six views with one listed twice lost the certificate where the five distinct views are certified,
review 34a M1), and a TLS search enumerates inlier sets of copies that can only be in or out together (34a M3).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..result import Attempt, TriangulationResult

__all__ = ["ViewMerge", "identical_views", "may_repeat_views", "SAME_CAMERA_TOL"]

#: cameras scaled to unit Frobenius norm (sign free) closer than this in every entry are the same camera.
SAME_CAMERA_TOL = 64 * np.finfo(float).eps
#: a fixed direction for the one-number sort key of a camera (any generic vector).
_KEY = np.sin(np.arange(1.0, 13.0) * 1.618)
#: the keys (:func:`_keys`, in [0, |_KEY|^2 < 7]) of copies of a camera in round-off differ by less than this
_KEY_TOL = 64 * SAME_CAMERA_TOL
_UP, _DOWN = 1.0 + 4 * np.finfo(float).eps, 1.0 - 4 * np.finfo(float).eps


@dataclass(frozen=True)
class ViewMerge:
    """The reduction of a view list with copies: ``group[i]`` the reduced view of view i, ``keep[g]`` the first
    view of group g, ``counts[g]`` its number of copies (module docstring)."""
    group: np.ndarray
    keep: np.ndarray
    counts: np.ndarray

    @property
    def n_views(self) -> int:
        return len(self.group)

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
        stop = getattr(opts, "lower_bound_stop", None)
        return opts if stop is None else opts.replace(lower_bound_stop=stop / self.ratio)

    def expand(self, res: TriangulationResult) -> TriangulationResult:
        """The reduced problem's result for the caller's N views (module docstring)."""
        r, g = self.ratio, self.group
        root = np.sqrt(self.counts.astype(float))[g]
        fields = {name: _scaled(getattr(res, name), r, up) for name, up in
                  (("gamma_lb", False), ("gamma_ub", True), ("gamma_ub_raw", True))}
        if res.image_points is not None:
            fields["image_points"] = res.image_points[g] / root[:, None]
        if res.residuals is not None:
            fields["residuals"] = res.residuals[g] / root
        for name in ("depths", "inliers"):
            if getattr(res, name) is not None:
                fields[name] = getattr(res, name)[g]
        fields["attempts"] = tuple(_attempt(a, r) for a in res.attempts)
        fields["message"] = (res.message + "; " if res.message else "") + self.describe()
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


def _attempt(a, r: float):
    if not isinstance(a, Attempt):
        return a
    return dataclasses.replace(a, gamma_lb=_scaled(a.gamma_lb, r, False), gamma_ub=_scaled(a.gamma_ub, r, True))


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
    U = _unit_cameras(A)
    rep = np.arange(N)
    for run in _runs(key[order]):                # views whose keys chain within _KEY_TOL: compared pairwise
        roots: list = []
        for j in order[run]:
            root = next((r for r in roots if _same(U, regions, thresholds, r, j)), None)
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
    return ViewMerge(group.astype(int), keep.astype(int), counts.astype(int))


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


def _unit_cameras(A: np.ndarray) -> np.ndarray:
    """Each camera (row of A (n, 12)) as a 12-vector of unit norm whose entry of largest magnitude is positive (sign
    and scale free; computed after an exact power-of-two scaling, so no camera over- or underflows)."""
    big = np.abs(A).max(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        A = A / np.exp2(np.ceil(np.log2(big)))[:, None]
        A = A / np.linalg.norm(A, axis=1)[:, None]
    sign = np.sign(A[np.arange(len(A)), np.abs(A).argmax(axis=1)])
    return A * sign[:, None]


def _same(U: np.ndarray, regions, thresholds, i: int, j: int) -> bool:
    """Views i and j are the same view (module docstring)."""
    if np.max(np.abs(U[i] - U[j])) > SAME_CAMERA_TOL:
        return False
    if thresholds is not None and not (thresholds[i] == thresholds[j]):
        return False
    if isinstance(regions, np.ndarray):                 # observed points (N, 2)
        return bool(np.array_equal(regions[i], regions[j]))
    return regions[i] == regions[j]
