"""Coplanar camera centres: the ceiling of Corollary 1's bound, and when escalating it is futile.

The spurious component.  Let the finite camera centres C_1, ..., C_N (N >= 3, not collinear) lie in one plane
pi (pi^T C_i = 0; with three views always: the trifocal plane), and let l_i be the image of pi in view i (the
line with P_i^T l_i ~ pi).  For x_i on l_i and x_j on l_j the back-projected rays both lie in pi, so they meet
(projectively): x_i^T F_ij x_j = 0 for every pair.  Every tuple (x_1, ..., x_N) with x_i on l_i therefore
satisfies all of Corollary 1's constraints (SPEC §7, the paper's epipolar form of m2 = 0), whether or not the rays
meet in one point.  With point regions x^_i, the cheapest such tuple costs

    s_pi = sum_i dist(x^_i, l_i)^2,

and since the feasible set of Corollary 1's program contains it, **every** Corollary 1 lower bound, at every
relaxation degree delta and in every formulation, satisfies

    f_LB(Corollary 1, delta) <= min over the epipolar variety of f <= s_pi.                         (C)

When the scene point lies in or near pi with noisy observations, s_pi is the out-of-plane part of the residuals
only (about half of the L2 optimum f* with isotropic noise: N of the 2N - 3 residual degrees of freedom), so
Corollary 1 cannot certify at any degree.  Theorem 1's minors (the trilinear relations among them) vanish only on
the images of scene points and are not bounded by (C) (:func:`tritools.solve.plan.exact_variety_step`).

Collinear centres (:func:`collinear_centres`: a straight drive along the optical axis, a rectified rig) lie in
every plane pi(theta) of the pencil through their line, so (C) holds for each: the ceiling is the best of them,
min_theta s_pi(theta) (:func:`pencil_ceiling`, an attained value on a grid of angles, refined), and the rule below
applies to the point plan with it (review 31a: a 5-view drive ran Corollary 1 at degree 4 twice, ~1.5 s, before
Theorem 1 certified).  The robust search's subset rules keep the coplanar ceiling only (its subsets' plans reach
the exact-variety views step themselves).

The futility rule (:func:`corollary1_futile`).  After a Corollary 1 step with lower bound f_lb and upper bound f_ub
(pixels^2), escalating Corollary 1 to a higher degree can raise the lower bound by at most s_pi - f_lb, and it
cannot certify unless f_ub (or a better upper bound it finds) comes within the certificate tolerance of s_pi.  So
the remaining Corollary 1 steps are skipped when

    * the centres are coplanar (:func:`centre_plane`: the smallest singular value of the centred centres is at
      most :data:`COPLANAR_RTOL` times the largest, the second one above it -- collinear centres have no unique
      plane), every region is a point and no two centres coincide (a pair with one centre carries a homography
      instead of an epipolar relation, which the spurious tuple need not satisfy);
    * the step's bound already sits on the spurious component: f_lb >= (1 - :data:`SITS_RTOL`) s_pi;
    * and the upper bound is clearly above it: s_pi <= (1 - :data:`GAP_RTOL`) f_ub.

The first two make (C) say that higher degrees add at most SITS_RTOL s_pi to the bound; the third that the gap
left is a thousand times the certificate tolerance.  Skipping a step never changes a reported bound's validity
(each reported bound is a step's rigorous bound); it only spends no time where a certificate cannot come from.
The robust search (:mod:`tritools.solve.robust`, :class:`tritools.solve.robust_bounds.SubsetBounds`) applies (C) to
view subsets S, whose ceiling is s_pi(S) = sum_{i in S} dist(x^_i, l_i)^2 (:func:`plane_distances2`; the lines of
the plane of all centres serve every subset): a weak subset's full-plan solve is skipped where (C) makes it futile
(:func:`subset_futile`), and the search stops (status not_certified, :data:`COPLANAR_BUDGET_NAME`) when the best
inlier set S* (at least :data:`CEILING_MIN_VIEWS` views) has a delta = 2 bound on its ceiling clearly below the cost
of its estimate (:func:`hopeless_subset`: the leaf of S* must be pruned for a certificate, which needs a bound of
L2*(S*) within the tolerance), or after :data:`COPLANAR_MAX_CEILING` subsets bounded on their ceilings.

The rule uses the step's upper bound as a stand-in for f*: where the estimate is far from the optimum and the
optimum sits on s_pi (a point exactly in pi without noise gives f* = s_pi = 0 and is certified at delta = 2
already), the skipped step could in principle have certified; measured, this does not occur on the turntable
cases of tests/test_coplanar.py.
"""
from __future__ import annotations

import math

import numpy as np

from ..model.constraints import Method
from ..model.stacked import centre_vectors
from ..result import Status
from .plan import exact_variety_applies

__all__ = ["centre_plane", "plane_lines", "spurious_cost", "corollary1_futile", "COPLANAR_RTOL", "SITS_RTOL",
           "GAP_RTOL", "FUTILE_MESSAGE", "futile_after", "subset_futile", "plane_distances2", "sits_on_ceiling",
           "COPLANAR_MAX_CEILING", "hopeless_subset", "CEILING_MIN_VIEWS", "COPLANAR_BUDGET_NAME",
           "pencil_ceiling", "plane_lines_raw", "PENCIL_SAMPLES", "collinear_centres",
           "nearly_collinear_centres", "NEAR_COLLINEAR_RTOL", "COLLINEAR_MESSAGE"]

#: centres are coplanar when the smallest singular value of the centred centres is at most this times the largest.
#: Not exact on purpose: the rule also needs the bound to sit on s_pi of the fitted plane, which a configuration far
#: from coplanar does not give (measured, N = 10 turntable, height jitter 1e-6 of the radius 2: delta = 4 bounds
#: equal to delta = 2 to 1e-4, the rule fires; jitter 1e-3: the delta = 2 bound is far above s_pi, it does not)
COPLANAR_RTOL = 1e-6
#: Corollary 1's bound "sits on" the spurious component when it is at least (1 - SITS_RTOL) s_pi
SITS_RTOL = 1e-3
#: ... and escalating is futile when s_pi is at most (1 - GAP_RTOL) times the upper bound
GAP_RTOL = 1e-3
#: centres are nearly collinear (:func:`nearly_collinear_centres`, the exact-variety views step's trigger) when the
#: second singular value of the centred distinct centres is at most this times the first (a drive of 8 frames 0.5 m
#: apart with 1 mm jitter: ~1e-3, where verification certifies; 0.1 mm: ~1e-4, where Corollary 1 stalls)
NEAR_COLLINEAR_RTOL = 1e-3
#: angles of the grid on which :func:`pencil_ceiling` looks for the best plane through collinear centres
PENCIL_SAMPLES = 360
#: the robust search stops (:meth:`tritools.solve.robust_bounds.SubsetBounds.node_budget`) once this many subsets of
#: at least :data:`CEILING_MIN_VIEWS` views got an uncertified delta = 2 bound sitting on their ceiling s_pi(S)
#: (:func:`sits_on_ceiling`): their bounds cannot rise at any degree, so the search cannot prune with them
COPLANAR_MAX_CEILING = 40
#: the smallest subsets counted: smaller ones get the exact-variety step (Theorem 1) when strengthened
CEILING_MIN_VIEWS = 5
#: the reason a robust search stopped at that budget (its result's message: "stopped by the ...")
COPLANAR_BUDGET_NAME = ("ceiling of coplanar camera centres (Corollary 1's subset bounds cannot exceed the cost of the "
                        "centres' plane component)")
#: the reason given for (nearly) collinear centres (:func:`collinear_centres`, :func:`nearly_collinear_centres`)
COLLINEAR_MESSAGE = "collinear camera centres: Corollary 1's bound is capped by the planes through their line"
#: the message of a point whose Corollary 1 steps were stopped by the futility rule
FUTILE_MESSAGE = ("{kind} camera centres: Corollary 1's bound sits on the spurious epipolar component "
                  "(s_pi = {s:.6g} px^2 < f_ub = {ub:.6g} px^2), higher degrees cannot certify")


def _finite_centres(cameras: np.ndarray) -> np.ndarray | None:
    """(N, 3) centres of at least three cameras, all finite (None otherwise)."""
    cams = np.asarray(cameras, float)
    if cams.ndim != 3 or cams.shape[0] < 3:
        return None
    a = centre_vectors(cams)
    w = a[:, 3]
    scale = np.max(np.abs(a[:, :3]), axis=1)
    if not np.all(np.isfinite(a)) or np.any(np.abs(w) <= 1e-12 * np.maximum(scale, 1e-300)):
        return None                                         # a centre at (or near) infinity
    return a[:, :3] / w[:, None]


def _centre_spread(cameras: np.ndarray):
    """(C (N, 3) finite centres, their mean, singular values and V^T of C - mean) when there are at least three, all
    finite and pairwise distinct (no two within 1e-9 of the spread); None otherwise."""
    C = _finite_centres(cameras)
    if C is None:
        return None
    mean = C.mean(axis=0)
    _, s, Vt = np.linalg.svd(C - mean, full_matrices=False)
    if s[0] == 0.0:
        return None
    gaps = np.linalg.norm(C[:, None, :] - C[None, :, :], axis=-1) + np.eye(len(C)) * s[0]
    if np.min(gaps) <= 1e-9 * s[0]:
        return None                                         # coinciding centres: a homography pair
    return C, mean, s, Vt


def centre_plane(cameras: np.ndarray) -> np.ndarray | None:
    """The plane pi (unit homogeneous 4-vector, pi^T C_i = 0) of the cameras' centres when they are finite, at
    least three, not collinear, pairwise distinct and coplanar within :data:`COPLANAR_RTOL`; None otherwise."""
    spread = _centre_spread(cameras)
    if spread is None:
        return None
    _, mean, s, Vt = spread
    if s[1] <= COPLANAR_RTOL * s[0] or s[2] > COPLANAR_RTOL * s[0]:
        return None
    n = Vt[2]
    pi = np.append(n, -n @ mean)
    return pi / np.linalg.norm(pi)


def _collinear_spread(cameras: np.ndarray):
    """:func:`_centre_spread` of centres on one line within :data:`COPLANAR_RTOL`; None otherwise."""
    spread = _centre_spread(cameras)
    return None if spread is None or spread[2][1] > COPLANAR_RTOL * spread[2][0] else spread


def collinear_centres(cameras: np.ndarray) -> str | None:
    """A reason (:data:`COLLINEAR_MESSAGE`) when the cameras' centres -- at least three, finite, pairwise distinct --
    lie on one line within :data:`COPLANAR_RTOL` (a rectified rig, a straight drive); None otherwise.  Every plane
    through that line holds every centre, so Corollary 1's epipolar variety holds the component of each of them and
    its bound can stop at the residual across the baseline alone, at every degree (review 30a F4: 0 of 10 rectified
    points of 3-7 views certified); the exact-variety steps apply as for coplanar centres."""
    return None if _collinear_spread(cameras) is None else COLLINEAR_MESSAGE


def nearly_collinear_centres(cameras: np.ndarray) -> str | None:
    """A reason when the cameras' distinct centres -- at least three, finite; coinciding ones (within 1e-9 of the
    spread: a pure rotation between two frames) counted once -- lie on one line within
    :data:`NEAR_COLLINEAR_RTOL` (the second singular value of the centred centres over the first): the trigger of
    Theorem 1's view-clique step (:mod:`tritools.solve.stages.exact`), which runs only where the plan did not
    certify.  Near the line Corollary 1's variety is close to holding the pencil's component and its bound stalls
    near its ceiling too (review 31a: drives with 0.1 mm jitter, 0 of 8 points of 8-12 views certified)."""
    C = _finite_centres(cameras)
    if C is None:
        return None
    span = float(np.max(np.ptp(C, axis=0)))
    near = np.triu(np.linalg.norm(C[:, None, :] - C[None, :, :], axis=-1) <= 1e-9 * span, 1)
    D = C[~near.any(axis=0)]                                # each centre unless an earlier one coincides with it
    if len(D) < 3 or span == 0.0:
        return None
    sv = np.linalg.svd(D - D.mean(axis=0), compute_uv=False)
    return None if sv[1] > NEAR_COLLINEAR_RTOL * sv[0] else COLLINEAR_MESSAGE


def plane_lines_raw(cameras: np.ndarray, pi: np.ndarray) -> np.ndarray:
    """(N, 3) image lines l_i of the plane ``pi``: P_i^T l_i = pi (least squares; pi holds the centre, so it lies
    in the column space of P_i^T), unscaled (linear in pi)."""
    return np.array([np.linalg.lstsq(P.T, pi, rcond=None)[0] for P in np.asarray(cameras, float)])


def plane_lines(cameras: np.ndarray, pi: np.ndarray) -> np.ndarray:
    """(N, 3) image lines l_i of the plane ``pi`` (:func:`plane_lines_raw`), each scaled to ||(l_1, l_2)|| = 1 (a
    signed point-line distance is l . (x, 1))."""
    lines = plane_lines_raw(cameras, pi)
    with np.errstate(divide="ignore", invalid="ignore"):    # a line at infinity: inf / NaN, no finite s_pi
        return lines / np.linalg.norm(lines[:, :2], axis=1, keepdims=True)


def plane_distances2(cameras: np.ndarray, points) -> np.ndarray | None:
    """(N,) squared distances dist(x^_i, l_i)^2 (pixels^2) of image points (N, 2) to the image lines of the
    centres' plane; None when the centres are not coplanar (:func:`centre_plane`).  For any subset S of the views,
    sum_{i in S} of them is a ceiling s_pi(S) of Corollary 1's bound of S (the tuple on the lines of this plane
    is feasible for S's epipolar relations too, whichever other planes S's centres lie in)."""
    pi = centre_plane(cameras)
    if pi is None:
        return None
    x = np.column_stack([np.asarray(points, float), np.ones(len(points))])
    d = np.einsum("ij,ij->i", plane_lines(cameras, pi), x)
    return d * d


def pencil_ceiling(cameras: np.ndarray, points) -> float | None:
    """For collinear centres (:func:`collinear_centres`), min over the planes pi(theta) through their line of
    s_pi(theta) = sum_i dist(x^_i, l_i(theta))^2 (pixels^2), found on a grid of :data:`PENCIL_SAMPLES` angles and
    refined; None when the centres are not collinear.  Every tuple on the lines of one plane of the pencil satisfies
    all epipolar relations, so each s_pi(theta) -- the minimum found or not -- caps Corollary 1's bound at every
    degree ((C) for the pencil: the ceiling is an attained value, never a bound this module reports).  With
    pi(theta) = cos(theta) pi_1 + sin(theta) pi_2 the lines are l_i(theta) = cos(theta) a_i + sin(theta) b_i."""
    spread = _collinear_spread(cameras)
    if spread is None:
        return None
    _, mean, _, Vt = spread
    pis = [np.append(n, -n @ mean) for n in Vt[1:3]]
    ab = [plane_lines_raw(cameras, pi) for pi in pis]
    x = np.column_stack([np.asarray(points, float), np.ones(len(points))])
    num = np.stack([np.einsum("ij,ij->i", m, x) for m in ab])             # (2, N): a_i . x, b_i . x
    dirs = np.stack([m[:, :2] for m in ab])                                # (2, N, 2)

    def cost(theta):
        c, s = np.cos(theta), np.sin(theta)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            d = (np.multiply.outer(c, num[0]) + np.multiply.outer(s, num[1])) ** 2 / np.sum(
                (np.multiply.outer(c, dirs[0]) + np.multiply.outer(s, dirs[1])) ** 2, axis=-1)
            return np.where(np.isnan(d), np.inf, d).sum(axis=-1)

    grid = np.linspace(0.0, np.pi, PENCIL_SAMPLES, endpoint=False)
    vals = cost(grid)
    k = int(np.argmin(vals))
    h = np.pi / PENCIL_SAMPLES
    for _ in range(40):                                      # a finer grid of 5 angles around the best, halved
        t = grid[k] + np.linspace(-h, h, 5)
        v = cost(t)
        j = int(np.argmin(v))
        grid, k, h = t, j, h / 2
        vals = v
    best = float(vals[k])
    return best if math.isfinite(best) else None


def spurious_cost(cameras: np.ndarray, regions, pencil: bool = True) -> float | None:
    """s_pi = sum_i dist(x^_i, l_i)^2 (pixels^2, module docstring) for point regions and coplanar centres, or (with
    ``pencil``) the best plane of the pencil through collinear centres (:func:`pencil_ceiling`); None when the
    centres are neither (:func:`centre_plane`) or a region is not a point."""
    if not all(r.is_point for r in regions):
        return None
    points = [r.center for r in regions]
    d2 = plane_distances2(cameras, points)
    s = (pencil_ceiling(cameras, points) if pencil else None) if d2 is None else float(np.sum(d2))
    return s if s is not None and math.isfinite(s) else None


def sits_on_ceiling(f_lb: float, d2: np.ndarray) -> bool:
    """Whether a Corollary 1 bound ``f_lb`` (pixels^2) of a subset sits on its ceiling s_pi(S) = sum ``d2``
    (within :data:`SITS_RTOL`): no Corollary 1 degree can raise it further than that."""
    s = float(np.sum(d2))
    return math.isfinite(s) and math.isfinite(f_lb) and f_lb >= (1.0 - SITS_RTOL) * s


def corollary1_futile(cameras: np.ndarray, regions, f_lb: float | None, f_ub: float | None,
                      pencil: bool = True) -> str | None:
    """The reason (:data:`FUTILE_MESSAGE`) why no Corollary 1 step of a higher degree can certify, after a step
    with bounds ``f_lb`` <= ``f_ub`` (pixels^2; module docstring's rule; ``pencil``: collinear centres too,
    :func:`spurious_cost`); None when the rule does not apply."""
    if f_lb is None or f_ub is None or not (math.isfinite(f_lb) and math.isfinite(f_ub)):
        return None
    s = spurious_cost(cameras, regions, pencil)
    if s is None or not sits_on_ceiling(f_lb, np.array([s])) or s > (1.0 - GAP_RTOL) * f_ub:
        return None
    kind = "coplanar" if centre_plane(cameras) is not None else "collinear"
    return FUTILE_MESSAGE.format(kind=kind, s=s, ub=f_ub)


def futile_after(cameras: np.ndarray, regions, steps, res) -> str | None:
    """After a NOT_CERTIFIED plan step's result ``res`` (gamma bounds in pixels), the reason to skip the rest of a
    plan ``steps`` made of Corollary 1 steps only (:func:`corollary1_futile` on f = 2N gamma^2); None otherwise."""
    if res.status != Status.NOT_CERTIFIED or any(s.method != Method.COROLLARY1 for s in steps):
        return None
    if res.gamma_lb is None or res.gamma_ub is None:
        return None
    n2 = 2 * len(regions)
    return corollary1_futile(cameras, regions, n2 * res.gamma_lb ** 2, n2 * res.gamma_ub ** 2)


def subset_futile(cameras: np.ndarray, regions, options, f_lb: float, X) -> str | None:
    """For the robust search's subsets (:meth:`tritools.solve.robust_bounds.SubsetBounds.strengthen`): the reason
    why solving this sub-problem with the full degree plan cannot certify it -- :func:`corollary1_futile` with the
    upper bound f(X) of its estimate ``X`` (world point, pixels^2) -- when the plan would hold Corollary 1 steps
    only (no exact-variety step, :func:`tritools.solve.plan.exact_variety_applies`); None otherwise."""
    if X is None or not all(r.is_point for r in regions):
        return None
    if exact_variety_applies(options, len(regions), 2 * len(regions)):
        return None
    h = np.asarray(cameras, float) @ np.append(np.asarray(X, float), 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = h[:, :2] / h[:, 2:] - np.array([p.center for p in regions])
    f_ub = float(np.sum(r * r))
    return corollary1_futile(cameras, regions, f_lb, f_ub, pencil=False)     # collinear: the plan's views step



def hopeless_subset(cameras: np.ndarray, points: np.ndarray, d2: np.ndarray, X) -> bool:
    """Whether the ceiling s_pi(S) = sum ``d2`` of a view subset S is at most (1 - :data:`GAP_RTOL`) times the cost
    of the estimate ``X`` on S (pixels^2).  Used on the robust search's best inlier set S* when its bound already
    sits on the ceiling (:func:`sits_on_ceiling`): the TLS certificate needs the leaf of S* pruned, i.e. a bound of
    L2*(S*) within the tolerance of the L2 part of the best value, and Corollary 1 gives at most s_pi(S*) < that."""
    h = np.asarray(cameras, float) @ np.append(np.asarray(X, float), 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = h[:, :2] / h[:, 2:] - np.asarray(points, float)
    f_ub = float(np.sum(r * r))
    s = float(np.sum(d2))
    return math.isfinite(f_ub) and math.isfinite(s) and s <= (1.0 - GAP_RTOL) * f_ub
