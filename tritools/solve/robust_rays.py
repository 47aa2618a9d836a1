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

__all__ = ["ray_candidates", "ray_samples_stack", "best_ray_samples", "sampled_pairs",
           "centre_pair_candidates", "view_ray", "camera_baseline", "SWEEP", "GOLDEN_STEPS", "MAX_RAYS",
           "CENTRE_PAIRS"]

#: depths of the geometric sweep along each ray: baseline * 10^k, k in [-3, 3] (this many).
SWEEP = 13
#: golden-section steps (in log depth) around the best depth of each ray.
GOLDEN_STEPS = 20
#: at most this many rays, each met by at most this many others (review 8 F1: all N rays, each at the depths
#: closest to all N - 1 others, screened against N views, is ~N^3 work -- 2-3 s at N = 200, not interruptible).
#: Above it the rays of the views nearest the search's best candidate are kept (the likely inliers), so the work
#: is linear in N; the candidates are only a ranking, every bound stays valid.
MAX_RAYS = 64
#: values of f_TLS along a ray within this relative distance of its minimum count as equal (:func:`_best_depth`)
TIE_REL = 1e-10
_GOLD = (math.sqrt(5.0) - 1.0) / 2.0


def _rays(C: np.ndarray, pts: np.ndarray):
    """Centres (N, 3), unit directions (N, 3) towards positive depth, and a mask of views whose M_i is
    invertible (others give no ray): :func:`_rays_stack` of one problem."""
    return tuple(a[0] for a in _rays_stack(C[None], pts[None]))


def view_ray(P: np.ndarray, u: np.ndarray):
    """(centre, unit direction toward positive depth) of the ray of image point ``u`` (2,) in camera ``P`` (3, 4), or
    None where M is singular or the numbers are not finite (:func:`_rays_one_by_one` of one view)."""
    centres, dirs, ok = _rays_one_by_one(np.asarray(P, float)[None], np.asarray(u, float)[None])
    return (centres[0], dirs[0]) if ok[0] else None


def _rays_one_by_one(C: np.ndarray, pts: np.ndarray):
    """:func:`_rays` view by view (a singular M_i gives no ray)."""
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


def _closest_depths_all(centres, dirs) -> list:
    """For each ray i, the depths t > 0 of its points closest to every other, non-parallel ray
    (:func:`_closest_depths` of one problem)."""
    t, good = _closest_depths(centres[None], dirs[None])
    return [t[0, i, good[0, i]] for i in range(len(centres))]


def _closest_depths(centres: np.ndarray, dirs: np.ndarray) -> tuple:
    """(t, good) (P, N, N) for P problems' rays (centres, unit directions u (P, N, 3)): the depth t[p, i, j] of the
    point of ray i closest to ray j, with b = C_j - C_i and k = u_i . u_j, t = (b . u_i - k b . u_j) / (1 - k^2);
    ``good`` where j != i, the rays are not parallel and t > 0."""
    b = centres[:, None, :, :] - centres[:, :, None, :]                            # b[p, i, j] = C_j - C_i
    k = dirs @ np.swapaxes(dirs, 1, 2)
    den = 1.0 - k * k
    with np.errstate(all="ignore"):
        t = (np.einsum("pijk,pik->pij", b, dirs) - k * np.einsum("pijk,pjk->pij", b, dirs)) / den
    good = (den > 1e-12) & np.isfinite(t) & (t > 0) & ~np.eye(centres.shape[1], dtype=bool)[None]
    return t, good


def camera_baseline(centres: np.ndarray) -> float:
    """The median distance between camera centres, or (coincident centres) max(1, |C|): :func:`_baselines` of one."""
    return float(_baselines(centres[None])[0])


def _baselines(centres: np.ndarray) -> np.ndarray:
    """(P,) the median distance between each problem's camera centres (P, N, 3), or (coincident centres, also to
    round-off: at most ``COINCIDENT_REL`` max |C_i|) max(1, max |C_i|)."""
    i, j = np.triu_indices(centres.shape[1], 1)
    d = np.linalg.norm(centres[:, i] - centres[:, j], axis=2)                     # (P, pairs)
    base = _finite_median(np.where(np.isfinite(d) & (d > 0), d, np.nan))
    far = np.maximum(1.0, np.max(np.linalg.norm(centres, axis=2), axis=1))
    return np.where(np.isfinite(base) & (base > COINCIDENT_REL * far), base, far)


#: centres closer than this times their distance from the origin coincide for the sweep: its deepest point, 1e3
#: baselines, would lie within 100 PROJECTION_DENOM_RTOL |C| of the centre, where no projection is defined (review 20
#: F2: centres 1.5e-6 apart 7.4e7 from the origin gave no finite candidate, numerical_failure without X)
COINCIDENT_REL = 1e-11


def ray_candidates(search) -> list:
    """Candidate points X (one per view with a ray, module docstring) for ``search`` (a
    :class:`tritools.solve.robust.TlsSearch`; its ``screen`` ranks candidates by f_TLS)."""
    C = search.C
    pts = search.x if search.points else np.array([r.closest_point(r.center) for r in search.regions], float)
    centres, dirs, ok = _rays(C, pts)
    views = _kept_views(search, ok)
    if views.size == 0:
        return []
    base = camera_baseline(centres[views])
    sweep = base * np.logspace(-3, 3, SWEEP)
    closest = _closest_depths_all(centres[views], dirs[views])
    ts = [np.unique(np.concatenate([sweep, t, [np.median(t)] if t.size else []])) for t in closest]
    f = search.screen(np.concatenate([centres[i] + t[:, None] * dirs[i] for i, t in zip(views, ts)]))
    f = np.where(np.isnan(f), np.inf, f)
    out, refine = [], []
    ends = np.cumsum([len(t) for t in ts]).tolist()
    for i, t, near, lo, hi in zip(views, ts, closest, [0] + ends[:-1], ends):
        fi = f[lo:hi]
        k = _best_depth(fi, t, near, base)
        out.append(centres[i] + t[k] * dirs[i])
        if fi[k] < search.best_f:          # refine only the rays that already beat the best candidate
            refine.append((i, t[k - 1] if k > 0 else t[0] / 10, t[k + 1] if k < len(t) - 1 else t[-1] * 10))
    if refine and not search.deadline.expired:
        r, lo, hi = (np.array(v) for v in zip(*refine))
        out += _golden(search, centres[r], dirs[r], np.log(lo), np.log(hi))
    return out


def _best_depth(fi: np.ndarray, t: np.ndarray, near: np.ndarray, base: float) -> int:
    """The index of the smallest value in ``fi`` (f_TLS at the depths ``t`` of one ray); among smallest values equal to
    :data:`TIE_REL` (the ray's own d_i^2 is round-off, ~1e-16 of f, in a georeferenced world)
    (every other view capped at c^2: the whole ray is optimal) the depth nearest, in log depth, to the median depth
    at which the ray meets the others (``near``; the baseline without any), so a free optimum is placed in the scene
    and not next to the camera centre, where rounding X moves the projections (review 8 F3: a georeferenced ray
    optimum lost its certificate to the rounding-spread guard)."""
    k = int(np.argmin(fi))
    ties = np.flatnonzero(fi <= fi[k] * (1 + TIE_REL))
    if ties.size < 2:
        return k
    ref = math.log(float(np.median(near)) if near.size else base)
    return int(ties[np.argmin(np.abs(np.log(t[ties]) - ref))])


def ray_samples_stack(C: np.ndarray, pts: np.ndarray):
    """The depth samples of :func:`ray_candidates` for P problems of N point views at once (no golden-section
    refinement: :func:`best_ray_samples` ranks them): ``(X, tie)``, X (P, N, K, 3) the points of each view's ray at
    the sweep depths (baseline * 10^[-3, 3], the median distance between camera centres) and at the depths closest to
    every other ray and their median (K = SWEEP + N + 1, in that order, the ray's own slot among the N NaN; NaN
    where a view has no ray or a depth is undefined), ``tie``
    (P, N, K) the distance in log depth to the ray's reference depth (the median closest depth, else the baseline:
    the tie rule of :func:`_best_depth`).  C (P, N, 3, 4), pts (P, N, 2)."""
    P, N = C.shape[:2]
    centres, dirs, ok = _rays_stack(C, pts)
    t, good = _closest_depths(centres, dirs)
    near = np.where(good & ok[:, :, None] & ok[:, None, :], t, np.nan)
    base, med = _baselines(centres), _finite_median(near)                       # (P,), (P, N)
    ref = np.where(np.isfinite(med), med, base[:, None])
    ts = np.concatenate([np.broadcast_to(base[:, None, None] * np.logspace(-3, 3, SWEEP), (P, N, SWEEP)), near,
                         med[:, :, None]], axis=2)
    ts = np.where(ok[:, :, None], ts, np.nan)
    X = centres[:, :, None, :] + ts[..., None] * dirs[:, :, None, :]
    with np.errstate(all="ignore"):
        tie = np.abs(np.log(ts) - np.log(ref)[:, :, None])
    return X, np.where(np.isfinite(tie), tie, np.inf)


def _finite_median(a: np.ndarray) -> np.ndarray:
    """The median of the non-NaN entries along the last axis (NaN where there are none): np.nanmedian without its
    masked-array cost (~0.7 ms a call)."""
    a = np.sort(a, axis=-1)                                  # NaN sorts last
    n = np.sum(~np.isnan(a), axis=-1, keepdims=True)
    lo = np.take_along_axis(a, np.maximum((n - 1) // 2, 0), axis=-1)
    hi = np.take_along_axis(a, np.minimum(n // 2, a.shape[-1] - 1), axis=-1)
    return np.where(n > 0, (lo + hi) / 2, np.nan)[..., 0]


def best_ray_samples(f: np.ndarray, tie: np.ndarray) -> np.ndarray:
    """The index (P, N) of each ray's best sample: the smallest f_TLS ``f`` (P, N, K; NaN counts as inf), among values
    equal to within :data:`TIE_REL` the one of smallest ``tie`` (:func:`ray_samples_stack`; the rule of
    :func:`_best_depth`)."""
    f = np.where(np.isnan(f), np.inf, f)
    lo = f.min(axis=2, keepdims=True)
    ties = f <= lo * (1 + TIE_REL)
    return np.argmin(np.where(ties, tie, np.inf), axis=2)


def _rays_stack(C: np.ndarray, pts: np.ndarray):
    """:func:`_rays` of P problems (C (P, N, 3, 4), pts (P, N, 2)): centres, unit directions (P, N, 3), mask (P, N);
    problem by problem where the stacked solve meets a singular M_i."""
    P, N = C.shape[:2]
    try:
        M, p = C[..., :3], C[..., 3]
        rhs = np.stack([-p, np.concatenate([pts, np.ones((P, N, 1))], axis=2)], axis=3)      # (P, N, 3, 2)
        with np.errstate(all="ignore"):
            sol = np.linalg.solve(M, rhs)
            c, d = sol[..., 0], sol[..., 1]
            n = np.linalg.norm(d, axis=2)
            ok = np.isfinite(c).all(axis=2) & np.isfinite(n) & (n > 0)
            dirs = np.where(ok[..., None], d / np.where(ok, n, 1.0)[..., None] * np.sign(np.linalg.det(M))[..., None],
                            0.0)
        return np.where(ok[..., None], c, 0.0), dirs, ok
    except np.linalg.LinAlgError:
        out = [_rays_one_by_one(Cp, xp) for Cp, xp in zip(C, pts)]
        return tuple(np.stack(a) for a in zip(*out))


def _kept_views(search, ok: np.ndarray) -> np.ndarray:
    """The views whose rays are searched: every view with a ray up to :data:`MAX_RAYS`, else the :data:`MAX_RAYS`
    of them with the smallest distances at the search's best candidate (evenly spaced views without one)."""
    views = np.nonzero(ok)[0]
    if views.size <= MAX_RAYS:
        return views
    if search.best_X is None:
        return views[np.linspace(0, views.size - 1, MAX_RAYS).astype(int)]
    d = np.asarray(search.residuals(search.best_X), float)[views]
    return np.sort(views[np.argsort(np.where(np.isfinite(d), d, np.inf), kind="stable")[:MAX_RAYS]])


def _golden(search, centres, dirs, a, b) -> list:
    """Golden-section search of f_TLS(C_i + e^s u_i) over s in [a_i, b_i], all rays together (one screen call
    per step); the final points.  The steps stop at the search's deadline (each screen call computes its first block
    whatever the time: 22 uninterruptible calls were ~30 ms past a 0.05 s limit at 400 views)."""
    def f(s):
        v = search.screen(centres + np.exp(s)[:, None] * dirs)
        return np.where(np.isnan(v), np.inf, v)

    x1, x2 = b - _GOLD * (b - a), a + _GOLD * (b - a)
    f1, f2 = f(x1), f(x2)
    for _ in range(GOLDEN_STEPS):
        if search.deadline.expired:
            break
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


def sampled_pairs(N: int, rng, limit: int) -> list:
    """The view pairs of the search's candidate stage: all N(N - 1)/2 (in ``itertools.combinations`` order), or
    ``limit`` of them drawn by ``rng.choice`` over that order, without building the full list (the same pairs, in
    the same order, as indexing ``list(combinations(range(N), 2))``; 79,800 pairs at N = 400)."""
    I, J = np.triu_indices(N, 1)                         # row-major: the order of itertools.combinations
    if I.size > limit:
        k = rng.choice(I.size, limit, replace=False)
        I, J = I[k], J[k]
    return [frozenset((int(a), int(b))) for a, b in zip(I, J)]


#: region-centre pairs whose DLT points a search of regions other than points screens first
#: (:func:`centre_pair_candidates`)
CENTRE_PAIRS = 8


def centre_pair_candidates(search) -> np.ndarray:
    """Anytime candidates of a search over regions other than points: the DLT points (M, 3) of the region centres
    of :data:`CENTRE_PAIRS` view pairs (all pairs up to that many; else drawn by :func:`sampled_pairs` from a stream
    of their own, so the search's later draws do not change).  Cheap -- one stacked DLT, and the caller screens them
    at CENTRE_PAIRS x N region distances -- they give a candidate with an inlier set before the L2 sub-problems
    (each a whole triangulation with regions) have returned one: a limit that cuts those short then reports this
    candidate instead of the local L2 estimate of every view, which the wrong matches pull away from every view
    (review 15 F3: gamma_UB c / sqrt 2, every view an outlier).  Only a ranking: the caller keeps a candidate by its
    exact f_TLS."""
    from ..model.stacked import dlt_stack

    pairs = np.array([sorted(p) for p in sampled_pairs(search.N, np.random.default_rng(1), CENTRE_PAIRS)], int)
    if not pairs.size:
        return np.zeros((0, 3))
    centres = np.array([np.asarray(r.center, float).reshape(2) for r in search.regions])
    with np.errstate(all="ignore"):
        X, ok = dlt_stack(search.C[pairs], centres[pairs])
    ok &= np.isfinite(X).all(axis=1)
    return X[ok]
