"""Single-view candidates of the TLS search: points on the back-projected ray of one view.

An X on the ray of a point of R_i has d_i(X) = 0, so

    f_TLS(X) = sum_{j != i} min(d_j(X)^2, c_j^2) <= sum_{j != i} c_j^2,

and with N = 2 views f*_TLS = min(L2*, c_1^2, c_2^2) exactly: an inlier set of one view is reached only on
such a ray.  The search's leaves with at most one inlier are bounded by c^2(O), the value of these points; an
upper bound that never visits the rays cannot meet that lower bound (review finding F6).

For each view i, with camera centre C_i (P_i = [M_i | p_i], C_i = -M_i^-1 p_i) and unit direction u_i =
M_i^-1 (x_i, 1) (sign: positive depth in view i), the 1-D problem min_t f_TLS(C_i + t u_i) over t > 0 is
searched by the depths t that come closest to every other view's ray, a geometric sweep of depths in units of
the camera baseline (one screen call for all rays), and golden-section refinement (in log t) around the best
of them, all rays together, for the rays whose best sampled value already beats the search's best candidate.
x_i is the region's point closest to its centre (a point of R_i for every region type).  The values are only
a ranking: the caller keeps a candidate by its exact f_TLS (:meth:`tritools.solve.robust.TlsSearch.offer`).
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["ray_candidates", "SWEEP", "GOLDEN_STEPS"]

#: depths of the geometric sweep along each ray: baseline * 10^k, k in [-3, 3] (this many).
SWEEP = 25
#: golden-section steps (in log depth) around the best depth of each ray.
GOLDEN_STEPS = 30
_GOLD = (math.sqrt(5.0) - 1.0) / 2.0


def _rays(C: np.ndarray, pts: np.ndarray):
    """Centres (N, 3), unit directions (N, 3) towards positive depth, and a mask of views whose M_i is
    invertible (others give no ray)."""
    N = len(C)
    centres, dirs, ok = np.zeros((N, 3)), np.zeros((N, 3)), np.zeros(N, bool)
    for i in range(N):
        M, p = C[i][:, :3], C[i][:, 3]
        try:
            c = -np.linalg.solve(M, p)
            d = np.linalg.solve(M, np.append(pts[i], 1.0))
        except np.linalg.LinAlgError:
            continue
        n = np.linalg.norm(d)
        if not (np.all(np.isfinite(c)) and np.isfinite(n) and n > 0):
            continue
        centres[i], dirs[i], ok[i] = c, d / n * np.sign(np.linalg.det(M)), True
    return centres, dirs, ok


def _closest_depths(centres, dirs, i: int) -> list:
    """Depths t > 0 on ray i of its points closest to every other (non-parallel) ray j."""
    out = []
    for j in range(len(centres)):
        if j == i:
            continue
        b = centres[j] - centres[i]
        k = float(dirs[i] @ dirs[j])
        den = 1.0 - k * k
        if den > 1e-12:
            t = (float(b @ dirs[i]) - k * float(b @ dirs[j])) / den
            if np.isfinite(t) and t > 0:
                out.append(t)
    return out


def _baseline(centres: np.ndarray) -> float:
    """The median distance between camera centres, or (coincident centres) max(1, |C|)."""
    d = np.linalg.norm(centres[:, None] - centres[None], axis=2)
    d = d[np.triu_indices(len(centres), 1)]
    d = d[np.isfinite(d) & (d > 0)]
    return float(np.median(d)) if d.size else max(1.0, float(np.max(np.linalg.norm(centres, axis=1))))


def ray_candidates(search) -> list:
    """Candidate points X (one per view with a ray, module docstring) for ``search`` (a
    :class:`tritools.solve.robust.TlsSearch`; its ``screen`` ranks candidates by f_TLS)."""
    C = search.C
    pts = search.x if search.points else np.array([r.closest_point(r.center) for r in search.regions], float)
    centres, dirs, ok = _rays(C, pts)
    views = np.nonzero(ok)[0]
    if views.size == 0:
        return []
    base = _baseline(centres[ok])
    sweep = base * np.logspace(-3, 3, SWEEP)
    ts = [np.unique(np.concatenate([sweep, _closest_depths(centres[ok], dirs[ok], int(np.sum(ok[:i])))]))
          for i in views]
    f = search.screen(np.concatenate([centres[i] + t[:, None] * dirs[i] for i, t in zip(views, ts)]))
    f = np.where(np.isnan(f), np.inf, f)
    out, refine = [], []
    for i, t, fi in zip(views, ts, np.split(f, np.cumsum([len(t) for t in ts])[:-1])):
        k = int(np.argmin(fi))
        out.append(centres[i] + t[k] * dirs[i])
        if fi[k] < search.best_f:          # refine only the rays that already beat the best candidate
            refine.append((i, t[k - 1] if k > 0 else t[0] / 10, t[k + 1] if k < len(t) - 1 else t[-1] * 10))
    if refine:
        r, lo, hi = (np.array(v) for v in zip(*refine))
        out += _golden(search, centres[r], dirs[r], np.log(lo), np.log(hi))
    return out


def _golden(search, centres, dirs, a, b) -> list:
    """Golden-section search of f_TLS(C_i + e^s u_i) over s in [a_i, b_i], all rays together (one screen call
    per step); the final points."""
    def f(s):
        v = search.screen(centres + np.exp(s)[:, None] * dirs)
        return np.where(np.isnan(v), np.inf, v)

    x1, x2 = b - _GOLD * (b - a), a + _GOLD * (b - a)
    f1, f2 = f(x1), f(x2)
    for _ in range(GOLDEN_STEPS):
        left = f1 <= f2                       # the minimum is in [a, x2]: move b
        b = np.where(left, x2, b)
        a = np.where(left, a, x1)
        x2n = np.where(left, x1, a + _GOLD * (b - a))
        x1n = np.where(left, b - _GOLD * (b - a), x2)
        x1, x2 = x1n, x2n
        fn = f(np.where(left, x1, x2))
        f1, f2 = np.where(left, fn, f2), np.where(left, f1, fn)
    s = np.where(f1 <= f2, x1, x2)
    return list(centres + np.exp(s)[:, None] * dirs)
