"""Vectorised twins of the scalar geometry of :mod:`tritools.model.geometry`, over stacks of problems.

Every function takes a leading problem axis M (cameras (M, N, 3, 4), points (M, N, 2)) and runs as numpy
operations over the whole stack; ``tests/test_stacked.py`` checks each against its scalar twin (``dlt``, ``project``,
``refine_l2`` with point regions, ``fundamental_matrix``, ``camera_center``; a few cameras' centres:
:mod:`tritools.model.centres_few`).  Problems whose data a function cannot handle are flagged in a boolean mask,
never raised on, so one bad problem does not stop the stack.

* :func:`null_vectors` -- camera centres a (P a = 0) from the signed 3x3 minors;
* :func:`dlt_stack` -- Hartley-normalised linear triangulation;
* :func:`project_stack` -- projections with a finite mask;
* :func:`refine_points_stack` -- Levenberg-Marquardt on sum_i ||Phi(X, P_i) - x_i||^2;
* :func:`fundamental_stack` -- F_ij from the cameras' 4 x 4 determinants, of view pairs (coincident centres flagged);
* :func:`fundamental_stack_both` -- the same of normalised cameras with the raw cameras' ``defined``;
* :func:`epipolar_quadratics` -- the quadratic parts of x~_i^T F_ij x~_j;
* :func:`pixel_scales` -- the image scale of each view at a point (the focal length in pixels for a
  finite camera), used by the normalisation's floor.
"""
from __future__ import annotations

import functools
import math

import numpy as np

from sospoly.analysis import SparseQuadratics
from sospoly import pow2_above_array

from .centres_few import few_distinct
from .fundamental_det import fundamental_determinants
from .geometry import POINT_AT_INFINITY_RTOL, PROJECTION_DENOM_RTOL, SAME_CENTER_RTOL
from .lm_one import FLOAT_MAX_VIEWS, LM_MAX_ITER, LM_STEP_RTOL, polish_floats, refine_floats, solve3

__all__ = ["null_vectors", "dlt_stack", "project_stack", "refine_points_stack", "fundamental_stack",
           "fundamental_stack_both",
           "epipolar_quadratics", "pixel_scales", "distinct_centres", "centre_vectors", "view_pairs", "band_pairs",
           "norms", "median_rows", "gauss_newton_polish", "project_quiet", "project_quiet_views", "project_one",
           "next_damping", "lm_accept", "solve3", "LM_MAX_ITER", "LM_STEP_RTOL"]


#: the 3x3 identity of the damped step (read-only: one array, not one per iteration).
_EYE3 = np.eye(3)
_EYE3.flags.writeable = False


def norms(a: np.ndarray, axis, keepdims: bool = False) -> np.ndarray:
    """``numpy.linalg.norm(a, axis=axis, keepdims=keepdims)`` (2-norm of vectors, Frobenius of matrices) of a real
    float array, without its per-call overhead: the same operations, sqrt(add.reduce(a * a)), so bit-identical
    (tests/test_stacked_single.py)."""
    return np.sqrt(np.add.reduce(a * a, axis=axis, keepdims=keepdims))


def median_rows(a: np.ndarray) -> np.ndarray:
    """``numpy.median(a, axis=1)`` of a 2-D float array, without its per-call overhead (3 numpy calls instead of
    ~30): the middle order statistic(s) of each row, (lo + hi) / 2 as numpy's mean of the two middle ones (lo / 1
    for an odd length), NaN for a row holding a NaN (NaNs sort last) or an empty row; bit-identical
    (tests/test_stacked_single.py)."""
    M, n = a.shape
    if n == 0:
        return np.full(M, np.nan)
    s = np.sort(a, axis=1)
    lo, hi = s[:, (n - 1) // 2], s[:, n // 2]
    med = lo if n % 2 else (lo + hi) / 2
    return np.where(np.isnan(s[:, -1]), np.nan, med)


@functools.lru_cache(maxsize=256)
def view_pairs(N: int) -> tuple[np.ndarray, np.ndarray]:
    """(I, J) of the view pairs i < j in the order of Corollary 1's constraints (cached, read-only)."""
    I, J = np.triu_indices(N, 1)
    I.flags.writeable = J.flags.writeable = False
    return I, J


#: the columns of the four 3x3 minors of a 3x4 matrix (column k left out) and their cofactor signs (-1)^k.
_MINOR_COLUMNS = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])
_MINOR_SIGNS = np.array([1.0, -1.0, 1.0, -1.0])
#: up to this many matrices the four minors come from one gather (fewer calls), above it minor by minor (no copy).
_GATHER_MAX = 512


def null_vectors(P: np.ndarray) -> np.ndarray:
    """Null vectors a (P a = 0) of a stack of 3x4 matrices (..., 3, 4), from the signed 3x3 minors
    (a_k = (-1)^k det P[:, columns != k], the cofactor expansion along the first row); ||a||^2 = det(P P^T)
    (Cauchy-Binet), 0 iff rank P < 3."""
    if P.size <= 12 * _GATHER_MAX:
        S = P[..., _MINOR_COLUMNS]                               # (..., 3 rows, 4 minors, 3 columns)
        return _det3([[S[..., r, :, c] for c in range(3)] for r in range(3)]) * _MINOR_SIGNS
    E = [[P[..., r, c] for c in range(4)] for r in range(3)]     # the 12 entries, each read once
    minors = [_det3([[row[c] for c in cols] for row in E]) for cols in _MINOR_COLUMNS.tolist()]
    return np.stack([minors[0], -minors[1], minors[2], -minors[3]], axis=-1)


def _det3(a: list) -> np.ndarray:
    """det of 3x3 matrices given entry by entry (a[r][c] arrays), expanded along the first row."""
    (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = a
    return (a00 * (a11 * a22 - a12 * a21)
            - a01 * (a10 * a22 - a12 * a20)
            + a02 * (a10 * a21 - a11 * a20))


def _smallest_eigvec(A: np.ndarray) -> np.ndarray:
    """Unit right singular vector of the smallest singular value of each A (M, p, 4): the eigenvector of
    the smallest eigenvalue of A^T A (4x4, one batched eigh)."""
    return np.linalg.eigh(np.einsum("mki,mkj->mij", A, A))[1][..., 0]


def dlt_stack(C: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`tritools.model.geometry.dlt` for a stack: C (M, N, 3, 4), x (M, N, 2) -> (X (M, 3), ok (M,)).

    The rows of M0 are P_i[k] - x_ik P_i[2] (k = 1, 2), each scaled to unit norm, and X~ is the eigenvector of the
    smallest eigenvalue of A^T A.  Hartley's similarity x' = s (x - c) (:func:`~tritools.model.geometry.dlt`)
    changes nothing here: its rows are s (P_i[k] - x_ik P_i[2]), the same rows up to the factor s that the unit
    scaling removes, so they are formed directly (fewer operations, and no cancellation of the translation
    c against x)."""
    A = (C[:, :, :2, :] - x[..., None] * C[:, :, 2:3, :]).reshape(len(x), -1, 4)
    nA = norms(A, axis=2, keepdims=True)
    A = A / np.where(nA > 0, nA, 1.0)
    w = _smallest_eigvec(A)
    ok = np.abs(w[:, 3]) > POINT_AT_INFINITY_RTOL
    return w[:, :3] / np.where(ok, w[:, 3], 1.0)[:, None], ok


def project_stack(C: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Projections Phi(X_m, P_mi) (M, N, 2), homogeneous images (M, N, 3) and a finite mask (M,)."""
    with np.errstate(over="ignore", invalid="ignore"):
        return project_quiet(C, X)


def project_quiet(C: np.ndarray, X: np.ndarray, absC2: np.ndarray | None = None, h: np.ndarray | None = None) -> tuple:
    """:func:`project_stack` for a caller that already ignores overflow and invalid operations (one
    ``np.errstate`` around a loop instead of one per projection); ``absC2``: |C[:, :, 2, :]| when the caller
    has it (the cameras of a loop do not change); ``h``: the homogeneous images when the caller computed them
    (more accurately: :func:`tritools.model.frame.project_world`)."""
    x, h, defined = project_quiet_views(C, X, absC2, h)
    return x, h, defined.all(axis=1)


def project_quiet_views(C: np.ndarray, X: np.ndarray, absC2: np.ndarray | None = None,
                        h: np.ndarray | None = None, rtol: float = PROJECTION_DENOM_RTOL) -> tuple:
    """:func:`project_quiet` with its rule per view: (x (M, N, 2), h (M, N, 3), defined (M, N)), a view undefined
    where its denominator is at round-off, |P_3 . X~| <= rtol |P_3| . |X~| (``PROJECTION_DENOM_RTOL``, the plain dot
    product's; :func:`tritools.model.frame.project_world` passes its compensated images' own; x is then the
    undivided pair h_1, h_2), or its projection is not finite."""
    Xh = np.concatenate([X, np.ones((len(X), 1))], axis=1)
    if h is None:
        h = np.einsum("mnij,mj->mni", C, Xh)
    den = h[..., 2]
    absC2 = np.abs(C[:, :, 2, :]) if absC2 is None else absC2
    tiny = np.abs(den) <= rtol * np.einsum("mnj,mj->mn", absC2, np.abs(Xh))
    x = h[..., :2] / np.where(tiny, 1.0, den)[..., None]
    return x, h, ~tiny & np.isfinite(x).all(axis=2)


def project_one(C: np.ndarray, X: np.ndarray) -> tuple:
    """The scalar twin of :func:`project_quiet` for one problem: (u (N, 2), h (N, 3), finite) for cameras C (N, 3, 4)
    and a point X (3,), the same rule (a denominator at round-off, |P_3 . X~| <= PROJECTION_DENOM_RTOL |P_3| . |X~|,
    or a non-finite projection: not finite).  Run under the caller's ``np.errstate(over="ignore",
    invalid="ignore")``."""
    Xh = np.append(X, 1.0)
    h = C @ Xh
    den = h[:, 2]
    if (np.abs(den) <= PROJECTION_DENOM_RTOL * (np.abs(C[:, 2, :]) @ np.abs(Xh))).any():
        return h[:, :2], h, False
    u = h[:, :2] / den[:, None]
    return u, h, bool(np.isfinite(u).all())


def damped_step(JtJ: np.ndarray, g: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """The Levenberg-Marquardt step -(J^T J + mu (1 + tr J^T J) / 3 I)^{-1} g for a stack (M, 3, 3), (M, 3),
    (M,), the damping scaled by (1 + tr J^T J) / 3; a pseudo-inverse where a system is singular (that row only:
    each row's step is the one it gets alone, in any stack)."""
    A = JtJ + mu[:, None, None] * _EYE3 * (1.0 + np.trace(JtJ, axis1=1, axis2=2))[:, None, None] / 3
    try:
        return -np.linalg.solve(A, g[..., None])[..., 0]
    except np.linalg.LinAlgError:
        return -np.array([_solve_or_pinv(a, b) for a, b in zip(A, g)]).reshape(g.shape)


def _solve_or_pinv(A: np.ndarray, g: np.ndarray) -> np.ndarray:
    """A^{-1} g for one row of :func:`damped_step` (the stacked solve's numbers), its pseudo-inverse's if singular."""
    try:
        return np.linalg.solve(A[None], g[None, :, None])[0, :, 0]
    except np.linalg.LinAlgError:
        return np.linalg.pinv(A) @ g


def refine_points_stack(C: np.ndarray, xhat: np.ndarray, X: np.ndarray, ok: np.ndarray, *, return_converged=False,
                        scalar: bool | None = None, max_iter: int = LM_MAX_ITER) -> tuple:
    """Levenberg-Marquardt on sum_i ||Phi(X, P_i) - x^_i||^2 from X (M, 3), for the problems where ``ok``;
    the twin of :func:`tritools.model.geometry.refine_l2` with point regions.  (X, ok), and with
    ``return_converged`` also the mask of the problems that stopped by the step rule (not stalled, not at
    ``max_iter``, LM_MAX_ITER by default): another run from their X would stop after one step.

    ``scalar``: run a stack of one through :func:`refine_point` (the same iteration on plain (N, 3, 4) arrays,
    ~3x cheaper for one problem; equal to the stacked code up to round-off, tests/test_scalar_twins.py); None
    (default): exactly when M = 1."""
    if (len(X) == 1) if scalar is None else scalar:
        return _refine_one_as_stack(C, xhat, X, ok, return_converged, max_iter)
    X = X.copy()
    converged = np.zeros(len(X), bool)
    mu = np.full(len(X), 1e-3)
    with np.errstate(over="ignore", invalid="ignore"):      # once, not once per projection
        absC2 = np.abs(C[:, :, 2, :])
        u, h, fin = project_quiet(C, X, absC2)
        cost = np.where(fin, np.add.reduce((u - xhat) ** 2, axis=(1, 2)), np.inf)
        ok = ok & fin
        active = np.nonzero(ok)[0]
        for _ in range(max_iter):
            if active.size == 0:
                break
            active = _lm_iteration(C, absC2, xhat, X, u, h, cost, mu, converged, active)
    ok = ok & np.isfinite(X).all(axis=1)
    return (X, ok, converged & ok) if return_converged else (X, ok)


def _lm_iteration(C, absC2, xhat, X, u, h, cost, mu, converged, active: np.ndarray) -> np.ndarray:
    """One Levenberg-Marquardt iteration of :func:`refine_points_stack` on the ``active`` problems: X, u, h, cost,
    mu and converged updated in place; the problems still iterating returned."""
    whole = active.size == len(X)       # no copies while every problem is still iterating
    Ca, xa, Xa, absCa = (C, xhat, X, absC2) if whole else (C[active], xhat[active], X[active], absC2[active])
    ua, ha = (u, h) if whole else (u[active], h[active])      # the projections at X, kept from the last step
    # d Phi / d X = (P[:2, :3] - u P[2, :3]) / (P[2] . X~)
    Jac = (Ca[..., :2, :3] - ua[..., None] * Ca[..., 2:3, :3]) / ha[..., 2][..., None, None]
    Jac = Jac.reshape(len(active), -1, 3)
    r = (ua - xa).reshape(len(active), -1)
    JtJ = np.einsum("mki,mkj->mij", Jac, Jac)
    g = np.einsum("mki,mk->mi", Jac, r)
    mu_a = mu if whole else mu[active]
    step = damped_step(JtJ, g, mu_a)
    Xt = Xa + step
    ut, ht, fint = project_quiet(Ca, Xt, absCa)
    ct = np.where(fint, np.add.reduce((ut - xa) ** 2, axis=(1, 2)), np.inf)
    better = np.isfinite(ct) & (ct <= (cost if whole else cost[active]))
    small = norms(step, axis=1) <= LM_STEP_RTOL * (1.0 + norms(Xa, axis=1))
    # (Xa, ua may be views of X, u: updated only after their last use)
    if whole and better.all():          # every problem accepts its step: whole arrays, no fancy indexing
        X[...], cost[...], u[...], h[...] = Xt, ct, ut, ht
    else:
        acc = active[better]
        X[acc], cost[acc], u[acc], h[acc] = Xt[better], ct[better], ut[better], ht[better]
    mu_a = next_damping(mu_a, better)
    mu[active] = mu_a
    stalled = mu_a > 1e12
    converged[active[small & ~stalled]] = True
    return active[~(small | stalled)]


def next_damping(mu: np.ndarray, better: np.ndarray) -> np.ndarray:
    """The Levenberg-Marquardt damping after a step: divided by 10 (floor 1e-12) where it was accepted, times 10
    where not -- the one rule of every LM loop in tritools."""
    return np.where(better, np.maximum(mu / 10, 1e-12), mu * 10)


def lm_accept(X: np.ndarray, cost: np.ndarray, mu: np.ndarray, active: np.ndarray, Xa: np.ndarray, step: np.ndarray,
              Xt: np.ndarray, ct: np.ndarray) -> np.ndarray:
    """Accept the trial points ``Xt`` (cost ``ct``) of the ``active`` problems where they do not raise the cost, update
    the damping (:func:`next_damping`), and return the problems still active: not converged (a step below
    ``LM_STEP_RTOL`` of |X| after an accepted step), not stalled (damping above 1e12) and not at cost 0.  ``X``,
    ``cost`` and ``mu`` are updated in place (the region LM loops of :mod:`tritools.solve.discs` / ``ellipses``)."""
    better = np.isfinite(ct) & (ct <= cost[active])
    X[active[better]] = Xt[better]
    cost[active[better]] = ct[better]
    mu[active] = next_damping(mu[active], better)
    small = np.linalg.norm(step, axis=1) <= LM_STEP_RTOL * (1.0 + np.linalg.norm(Xa, axis=1))
    done = (better & small) | (mu[active] > 1e12) | (cost[active] == 0)
    return active[~done]


def gauss_newton_polish(C: np.ndarray, xhat: np.ndarray, X: np.ndarray, ok: np.ndarray,
                        scalar: bool | None = None) -> np.ndarray:
    """X (M, 3) after one undamped Gauss-Newton step on sum_i ||Phi(X, P_i) - x^_i||^2, kept only where it lowers
    the cost strictly (elsewhere X unchanged).  The Levenberg-Marquardt iteration damps every step by at least
    1e-12 (1 + tr J^T J) / 3; a direction of J^T J weaker than that (a tiny baseline: the depth, eigenvalues ~1e-13
    of the largest at zero noise) is then crossed only by halves and the step rule stops it early, at a cost far
    above round-off.  One exact step finishes that direction; where it does not help, nothing changes.  ``scalar``:
    as in :func:`refine_points_stack` (None: a stack of one runs the scalar twin)."""
    if (len(X) == 1) if scalar is None else scalar:     # a stack of one: the scalar twin (tests/test_scalar_twins.py)
        return _gauss_newton_one(C[0], xhat[0], X[0])[None] if ok[0] else X.copy()
    act = np.nonzero(ok)[0]
    X = X.copy()
    if act.size == 0:
        return X
    Ca, xa, Xa = C[act], xhat[act], X[act]
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        u, h, fin = project_quiet(Ca, Xa)
        cost = np.where(fin, np.add.reduce((u - xa) ** 2, axis=(1, 2)), np.inf)
        Jac = (Ca[..., :2, :3] - u[..., None] * Ca[..., 2:3, :3]) / h[..., 2][..., None, None]
        Jac = Jac.reshape(len(act), -1, 3)
        r = (u - xa).reshape(len(act), -1)
        JtJ = np.einsum("mki,mkj->mij", Jac, Jac)
        step = damped_step(JtJ, np.einsum("mki,mk->mi", Jac, r), np.zeros(len(act)))
        Xt = Xa + step
        ut, _, fint = project_quiet(Ca, Xt)
        ct = np.where(fint, np.add.reduce((ut - xa) ** 2, axis=(1, 2)), np.inf)
    better = fin & np.isfinite(ct) & (ct < cost) & np.isfinite(Xt).all(axis=1)
    X[act[better]] = Xt[better]
    return X


def _gauss_newton_one(C: np.ndarray, xhat: np.ndarray, X: np.ndarray) -> np.ndarray:
    """:func:`gauss_newton_polish` of one problem on plain arrays (:class:`_View`, :func:`damped_step_one` with
    mu = 0; for a few views :func:`~tritools.model.lm_one.polish_floats`): equal to the stacked step up to round-off."""
    if len(C) <= FLOAT_MAX_VIEWS:
        return polish_floats(C, xhat, X)
    cams = _View(C)
    X = np.array(X, float)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        at = cams.project(X, xhat)
        if at is None or not math.isfinite(at[2]):
            return X
        u, den, cost, r = at
        J = ((cams.A01 - u[:, :, None] * cams.A2) / den[:, None, None]).reshape(-1, 3)
        Xt = X + damped_step_one(J.T @ J, J.T @ r, 0.0)
        trial = cams.project(Xt, xhat)
    if trial is not None and math.isfinite(trial[2]) and trial[2] < cost and np.isfinite(Xt).all():
        return Xt
    return X


def _refine_one_as_stack(C, xhat, X, ok, return_converged: bool, max_iter: int = LM_MAX_ITER) -> tuple:
    """:func:`refine_point` on the one problem of a stack (M = 1), with the stack's return shapes."""
    if len(X) != 1:
        raise ValueError(f"refine_points_stack: scalar=True needs a stack of one problem, got {len(X)}")
    X1, ok1, conv1 = refine_point(C[0], xhat[0], X[0], bool(ok[0]), max_iter=max_iter)
    out = (X1[None], np.array([ok1]))
    return out + (np.array([conv1]),) if return_converged else out


class _View:
    """The cameras of one problem split for :func:`refine_point`: h = A X + b per view, and the magnitudes of
    the third rows (the denominator's scale in the rule of :func:`project_stack`)."""
    __slots__ = ("A", "b", "A01", "A2", "absA2", "absb2")

    def __init__(self, C: np.ndarray):
        self.A, self.b = C[:, :, :3], C[:, :, 3]
        self.A01, self.A2 = self.A[:, :2, :], self.A[:, 2:3, :]
        self.absA2, self.absb2 = np.abs(C[:, 2, :3]), np.abs(C[:, 2, 3])

    def project(self, X: np.ndarray, xhat: np.ndarray) -> tuple | None:
        """(u (N, 2), den (N,), cost sum ||u - x^||^2 (inf on overflow), u - x^ flattened) at X, or None where
        :func:`project_stack` flags the problem (a denominator at round-off, |P_3 . X~| <= PROJECTION_DENOM_RTOL
        |P_3| . |X~|, or a non-finite projection).  Run under ``np.errstate(over="ignore", invalid="ignore")``."""
        h = self.A @ X + self.b
        den = h[:, 2]
        if (np.abs(den) <= PROJECTION_DENOM_RTOL * (self.absA2 @ np.abs(X) + self.absb2)).any():
            return None
        u = h[:, :2] / den[:, None]
        r = (u - xhat).ravel()
        cost = float(r @ r)
        if not math.isfinite(cost) and not np.isfinite(u).all():     # (a non-finite u gives a non-finite cost)
            return None
        return u, den, cost, r


def damped_step_one(JtJ: np.ndarray, g: np.ndarray, mu: float) -> np.ndarray:
    """The scalar twin of :func:`damped_step`: -(J^T J + mu (1 + tr J^T J) / 3 I)^{-1} g for one 3x3 system
    (:func:`solve3`; the pseudo-inverse where it is exactly singular)."""
    A = JtJ.tolist()
    damp = mu * (1.0 + (A[0][0] + A[1][1] + A[2][2])) / 3
    for k in range(3):
        A[k][k] += damp
    x = solve3(A, g.tolist())
    if x is None:
        return -(np.linalg.pinv(np.array(A)) @ g)
    return -np.array(x)


def refine_point(C: np.ndarray, xhat: np.ndarray, X: np.ndarray, ok: bool = True, *, max_iter: int = LM_MAX_ITER):
    """The scalar (M = 1) twin of :func:`refine_points_stack`: the same Levenberg-Marquardt iteration on one problem,
    cameras C (N, 3, 4), observed points x^ (N, 2), start X (3,) -- minimising sum_i ||Phi(X, P_i) - x^_i||^2 with the
    Jacobian d Phi / d X = (P[:2, :3] - u P[2, :3]) / (P[2] . X~), the damped step of :func:`damped_step_one`, a step
    accepted iff the cost does not increase, mu / 10 on acceptance (floor 1e-12) and x 10 otherwise, stop when ||step||
    <= LM_STEP_RTOL (1 + ||X||) (converged) or mu > 1e12 (stalled) or after ``max_iter`` (LM_MAX_ITER) iterations.
    Plain (N, 2, 3) arrays and a 3x3 solve on floats instead of the stack's einsum and batched solve -- up to
    ``FLOAT_MAX_VIEWS`` views the whole iteration on Python floats (:func:`tritools.model.lm_one.refine_floats`) --
    so equal to it up to round-off only. (X, ok, converged)."""
    X = np.array(X, float)
    if not ok:
        return X, False, False
    if len(C) <= FLOAT_MAX_VIEWS:                 # a few views: the same iteration on floats (issue #22)
        return refine_floats(C, xhat, X, max_iter)
    cams = _View(C)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        at = cams.project(X, xhat)
        if at is None:
            return X, False, False
        converged = _lm_loop(cams, xhat, X, at, max_iter)
    return X, bool(np.isfinite(X).all()), converged


def _lm_loop(cams: _View, xhat: np.ndarray, X: np.ndarray, at: tuple, max_iter: int = LM_MAX_ITER) -> bool:
    """The iterations of :func:`refine_point` (X updated in place); True when stopped by the step rule."""
    u, den, cost, r = at
    mu = 1e-3
    for _ in range(max_iter):
        J = ((cams.A01 - u[:, :, None] * cams.A2) / den[:, None, None]).reshape(-1, 3)
        Jt = J.T
        step = damped_step_one(Jt @ J, Jt @ r, mu)
        Xt = X + step
        trial = cams.project(Xt, xhat)
        better = trial is not None and math.isfinite(trial[2]) and trial[2] <= cost
        small = math.sqrt(float(step @ step)) <= LM_STEP_RTOL * (1.0 + math.sqrt(float(X @ X)))
        if better:
            X[...] = Xt
            u, den, cost, r = trial
        mu = max(mu / 10, 1e-12) if better else mu * 10
        stalled = mu > 1e12
        if small or stalled:
            return small and not stalled
    return False


def band_pairs(N: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """(I, J) of the view pairs (i, i + d), 1 <= d <= width, ordered by i then d: a band of pairs whose
    constraints couple only views at most ``width`` apart (for width >= 2 a chain of view triangles, 2N - 3
    pairs at width 2, generically as many independent constraints as all N(N - 1)/2 pairs)."""
    I = [i for i in range(N) for d in range(1, width + 1) if i + d < N]
    J = [i + d for i in range(N) for d in range(1, width + 1) if i + d < N]
    return np.array(I, dtype=int), np.array(J, dtype=int)


def centre_vectors(C: np.ndarray) -> np.ndarray:
    """Null vectors (..., 4) of cameras (..., 3, 4) for deciding which centres coincide: the signed minors
    (:func:`null_vectors`) of the camera with rows 1 and 2 made orthogonal to row 3 (twice) -- an image homography,
    so the same null space, but a matrix whose rows are no longer nearly parallel when the principal point is far
    from the focal length (1e6 px): the minors then carry ~1e-13 instead of ~1e-10 relative error.  Each camera is
    divided by its largest entry and row 3 scaled to unit norm first (exact in what it decides)."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        m = np.maximum.reduce(np.abs(C).reshape(C.shape[:-2] + (12,)), axis=-1)[..., None, None]
        C = C / np.where(m > 0, m, 1.0)
        r3 = C[..., 2:3, :]
        n3 = norms(r3, axis=-1, keepdims=True)
        u3 = r3 / np.where(n3 > 0, n3, 1.0)
        r = C[..., :2, :]
        r = r - np.add.reduce(r * u3, axis=-1, keepdims=True) * u3
        r = r - np.add.reduce(r * u3, axis=-1, keepdims=True) * u3
        return null_vectors(np.concatenate([r, u3], axis=-2))


def distinct_centres(a_i: np.ndarray, a_j: np.ndarray) -> np.ndarray:
    """Do the camera centres a_i, a_j (homogeneous null vectors (..., 4), any scale) differ?  True where
    sin(angle(a_i, a_j)) = ||a_i ^ a_j|| / (||a_i|| ||a_j||) > SAME_CENTER_RTOL, with
    ||a_i ^ a_j||^2 = sum_{k<l} (a_ik a_jl - a_il a_jk)^2 (the Plucker coordinates of the baseline; all zero iff
    the centres coincide), evaluated as ||u - (u . w) w|| for the unit vectors u, w (absolute error ~1e-16).

    Invariant to the scale of each camera (a_i scales by k^3 and cancels) and to any image homography (it does not
    change the null vector), unlike a threshold on ||F_ij||: F = [P_i a_j]_x P_i P_j^+ scales like
    |P_i|^2 |a_j| |P_j^+| and, for cameras with pixel coordinates ~1e6 (principal point far from the focal length),
    a bound ``||F|| > rtol |P_i| |P_j|`` both dropped distinct pairs and kept coincident ones depending on the cameras'
    scales (tests/test_centres.py).  Exactly duplicated views have a_i = a_j bit for bit, so sin = 0: always
    coincident.  Limit: the null vectors themselves are only as accurate as the cameras' conditioning allows
    (a principal point at 1e6 px with a focal length of ~1 px leaves them uncertain at ~1e-5)."""
    ni, nj = norms(a_i, axis=-1, keepdims=True), norms(a_j, axis=-1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        u, w = a_i / ni, a_j / nj
        # ||u ^ w|| = ||u - (u . w) w|| for unit u, w (the component of u off w: no cancellation in 1 - (u . w)^2)
        sin = norms(u - np.add.reduce(u * w, axis=-1, keepdims=True) * w, axis=-1)
        return (sin > SAME_CENTER_RTOL) & (ni[..., 0] > 0) & (nj[..., 0] > 0)


def fundamental_stack(C: np.ndarray, pairs: tuple | None = None, errors: bool = False) -> tuple:
    """(F (M, K, 3, 3) unit Frobenius norm, defined (M, K)) for the view pairs ``pairs`` = (I, J) (default: all,
    :func:`view_pairs`): the exact fundamental matrix of the float cameras (SPEC §7, x_i^T F_ij x_j = 0), its entries
    the 4 x 4 determinants from the cameras' 2 x 2 minors (in double; longdouble where double would underflow)
    (:func:`tritools.model.fundamental_det.fundamental_determinants`); ``defined`` is False where the two camera
    centres coincide (:func:`distinct_centres` of :func:`centre_vectors`, invariant to the cameras' scales and image
    homographies) or F is not finite or vanishes.  ``errors``: also (M, K) proven bounds of ||F - lambda F_exact||_F
    (inf where not defined), the ``proven`` errors of :func:`tritools.model.epipolar_data.epipolar_errors`."""
    I, J = view_pairs(C.shape[1]) if pairs is None else pairs
    F, ok, e = fundamental_determinants(C, I, J)
    few = few_distinct(C, I, J)                         # a single call's few cameras: the same numbers
    if few is None:
        c = centre_vectors(C)
        few = distinct_centres(c[:, I], c[:, J])
    defined = few & ok
    F = np.where(defined[..., None, None], F, 0.0)
    return (F, defined, np.where(defined, e, np.inf)) if errors else (F, defined)


def fundamental_stack_both(Cn: np.ndarray, C: np.ndarray, pairs: tuple | None = None) -> tuple:
    """(F, defined, raw defined, E) of P problems: :func:`fundamental_stack` (with ``errors``) of the normalised
    cameras Cn (P, N, 3, 4) and the ``defined`` of the raw cameras C (the same shape), in one vectorised call.
    One centre or not is decided on the raw cameras too (CentreRelations' rule): the programs hold a pair's
    constraint only where both say defined (or drop it where the raw cameras say one centre)."""
    P = len(Cn)
    F, defined, E = fundamental_stack(np.concatenate([Cn, C]), pairs, errors=True)
    return F[:P], defined[:P], defined[P:], E[:P]


def epipolar_quadratics(F: np.ndarray, N: int, pairs: tuple | None = None):
    """Quadratic parts (g0 (M, K), g1 (M, K, 2N), G2) of g_ij(v) = x~_i^T F_ij x~_j over
    v = (x_11, x_12, ..., x_N2), for F (M, K, 3, 3) in the order of ``pairs`` (default :func:`view_pairs`); G2 as
    :class:`sospoly.analysis.verify.SparseQuadratics` (8 entries per pair, so memory grows like N^2, not N^4)."""
    M, K = F.shape[:2]
    k, lin, ks, ii, jj = _quadratic_index(N) if pairs is None else _quadratic_index_of(*pairs)
    g0 = F[..., 2, 2]
    g1 = np.zeros((M, K, 2 * N))
    vals = []
    for a_ in range(2):
        g1[:, k, lin[0][a_]] = F[:, :, a_, 2]
        g1[:, k, lin[1][a_]] = F[:, :, 2, a_]
        for b_ in range(2):
            half = F[:, :, a_, b_] / 2
            vals += [half, half]
    G2 = SparseQuadratics(ks, ii, jj, np.concatenate(vals, axis=1))
    return g0, g1, G2


@functools.lru_cache(maxsize=64)
def _quadratic_index(N: int) -> tuple:
    """:func:`_quadratic_index_of` the pairs of :func:`view_pairs` (cached, read-only: they depend on N only)."""
    out = _quadratic_index_of(*view_pairs(N))
    for a in (out[0], *out[1][0], *out[1][1], *out[2:]):
        a.flags.writeable = False
    return out


def _quadratic_index_of(I: np.ndarray, J: np.ndarray) -> tuple:
    """The indices of :func:`epipolar_quadratics` for the pairs (I, J): (k, ((2I, 2I + 1), (2J, 2J + 1)), and the
    pair, row and column of the 8 entries per pair of G2, in the order of its values)."""
    k = np.arange(len(I))
    lin = ((2 * I, 2 * I + 1), (2 * J, 2 * J + 1))
    ks, ii, jj = [], [], []
    for a_ in range(2):
        for b_ in range(2):
            ks += [k, k]
            ii += [lin[0][a_], lin[1][b_]]
            jj += [lin[1][b_], lin[0][a_]]
    return k, lin, np.concatenate(ks), np.concatenate(ii), np.concatenate(jj)


def pixel_scales(C: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The image scale of each view (M, N): sigma_max(P[:2, :3] - x P[2, :3]) / ||P[2, :3]||, i.e. pixels per
    radian at the observed point x (the focal length, up to the obliquity, for a finite camera K [R | t]).
    Invariant to the camera's scale, image translations and similarities of the world frame; NaN where the
    camera has no finite depth direction (||P[2, :3]|| = 0)."""
    B = C[..., :2, :3] - x[..., :, None] * C[..., 2:3, :3]
    d = norms(C[..., 2, :3], axis=-1)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        return np.where(d > 0, sigma_max_2x3(B) / d, np.nan)


def sigma_max_2x3(B: np.ndarray) -> np.ndarray:
    """The largest singular value of 2x3 matrices (..., 2, 3) in closed form: sigma_max^2 is the largest eigenvalue
    of B B^T = [[p, q], [q, r]], (p + r) / 2 + sqrt(((p - r) / 2)^2 + q^2) -- a sum of non-negative terms, so
    relatively accurate to a few ulps (tests/test_scalar_twins.py checks it against ``numpy.linalg.svd``) at a
    fraction of the cost of a batched SVD call.  Each matrix is divided by a power of two near its largest entry
    first (exact), so nothing overflows or underflows; NaN / inf propagate (the SVD would raise)."""
    m = np.maximum.reduce(np.abs(B).reshape(B.shape[:-2] + (6,)), axis=-1)
    k = pow2_above_array(m)
    B = B / k[..., None, None]
    b0, b1 = B[..., 0, :], B[..., 1, :]
    p, r, q = np.add.reduce(b0 * b0, axis=-1), np.add.reduce(b1 * b1, axis=-1), np.add.reduce(b0 * b1, axis=-1)
    h = (p - r) / 2
    return k * np.sqrt((p + r) / 2 + np.sqrt(h * h + q * q))
