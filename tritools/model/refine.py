"""The residuals of the local L2 refinement (:func:`tritools.model.geometry.refine_l2`) and its cost bound.

The refinement minimises gamma(X)^2 = sum_i ||x_i - y_i||^2 / 2N (SPEC §1) by Levenberg-Marquardt on the residuals
r_i(X) = x_i - y_i, x_i = Phi(X, P_i) and y_i the closest point of the region R_i to x_i.  For a point region
y_i = c_i; for a filled disc of radius rho_i around c_i, y_i = c_i + rho_i e_i / |e_i| outside it (e_i = x_i - c_i)
and x_i inside, so

    r_i = e_i max(0, 1 - rho_i / |e_i|),

one numpy expression for all views (:func:`disc_residuals`; other regions: a loop over their ``closest_point``);
gamma itself likewise (:func:`gamma_discs`, used by :func:`tritools.model.geometry.gamma_validated`): at N = 400 the
loops cost ~30 ms per evaluation, the stacked expressions well under 1 ms.

The cost bound.  The refinement also runs after a time limit has passed: the estimate of last resort, which the
trivial bound gamma* >= 0 may certify (:mod:`tritools.solve.trivial`), comes from it.  Past the active deadline
(:func:`sospoly.budget.active_deadline`) it may evaluate the residuals at most :func:`evaluations_after` more times
(work in proportion to N views: :data:`VIEW_EVALS_AFTER_DEADLINE` stacked evaluations, never fewer than
:data:`MIN_EVALS_AFTER_DEADLINE`; through the regions' own closest points about
:data:`LOOPED_VIEW_EVALS_AFTER_DEADLINE` region distances, never fewer than :data:`MIN_LOOPED_EVALS_AFTER_DEADLINE`
evaluations), and past :func:`evaluations_floor` (the looped start, or the stacked fewest) it also stops once
:data:`OVERRUN_SHARE_AFTER_DEADLINE` of the time limit has gone by since the deadline; it then stops with the best
iterate so far.  Any X is a valid
estimate (gamma(X) >= gamma*), so stopping early only makes gamma_UB less tight.
"""
from __future__ import annotations

import numpy as np

from sospoly.budget import active_deadline

from .regions.stack import RegionStack

__all__ = ["residual_function", "residual_jacobian", "disc_residuals", "disc_jacobian", "disc_shapes", "gamma_discs",
           "EvaluationGuard", "RefinementStopped", "evaluations_after", "evaluations_floor", "MIN_EVALS_AFTER_DEADLINE",
           "OVERRUN_SHARE_AFTER_DEADLINE",
           "VIEW_EVALS_AFTER_DEADLINE", "LOOPED_VIEW_EVALS_AFTER_DEADLINE", "MIN_LOOPED_EVALS_AFTER_DEADLINE",
           "FAR_RESIDUAL"]

#: the residual of every view where a projection is at infinity (its denominator below 1e-300)
FAR_RESIDUAL = 1e150
#: evaluations of the residuals the refinement may still make once the deadline has passed, at least (three
#: parameters: four evaluations per Levenberg-Marquardt iteration, so six iterations)
MIN_EVALS_AFTER_DEADLINE = 24
#: ... and in region distances (views x evaluations): 400 evaluations (scipy's default max_nfev) up to 20 views
VIEW_EVALS_AFTER_DEADLINE = 8000
#: ... in region distances through the regions' own ``closest_point`` (the loop of the other region kinds:
#: 10-140 us each, so 8000 of them were 0.1-0.5 s past a limit with 16-30 mixed regions): 133 evaluations at 3
#: views (~33 Levenberg-Marquardt iterations), 25 at 16, 13 at 30, one iteration at least
LOOPED_VIEW_EVALS_AFTER_DEADLINE = 400
#: the fewest evaluations of the loop past the deadline: the start and its forward-difference Jacobian
MIN_LOOPED_EVALS_AFTER_DEADLINE = 4
#: past the deadline, beyond those fewest evaluations, the refinement also stops once the time since the deadline
#: exceeds this share of the time limit (:meth:`sospoly.budget.Deadline.overrun`): at a 0.2 s limit the loop's 400
#: region distances (~50 ms for polytopes) were a quarter of the limit
OVERRUN_SHARE_AFTER_DEADLINE = 0.03


def disc_residuals(X, cameras: np.ndarray, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """r_i (module docstring) stacked (2N,) for point (radius 0) and disc regions; :data:`FAR_RESIDUAL` everywhere
    where a projection is at infinity."""
    h = cameras @ np.append(np.asarray(X, float), 1.0)
    if np.any(np.abs(h[:, 2]) < 1e-300):
        return np.full(2 * len(cameras), FAR_RESIDUAL)
    e = h[:, :2] / h[:, 2:] - centres
    if np.any(radii):
        n = np.hypot(e[:, 0], e[:, 1])
        with np.errstate(divide="ignore", invalid="ignore"):
            e = e * np.where(n > radii, 1.0 - radii / n, 0.0)[:, None]
    return e.ravel()


def disc_jacobian(X, cameras: np.ndarray, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """d r / d X (2N, 3) of :func:`disc_residuals`, analytic: with h = P_i (X, 1), x_i = h_{1:2} / h_3,
    d x_i / d X = (P_i[1:2, 1:3] - x_i P_i[3, 1:3]) / h_3; d r_i / d e_i = I for a point, and for a disc
    (1 - rho_i / |e_i|) I + rho_i e_i e_i^T / |e_i|^3 outside it, 0 inside.  Zero where a projection is at infinity
    (the residuals are the constant :data:`FAR_RESIDUAL` there)."""
    N = len(cameras)
    h = cameras @ np.append(np.asarray(X, float), 1.0)
    if np.any(np.abs(h[:, 2]) < 1e-300):
        return np.zeros((2 * N, 3))
    x = h[:, :2] / h[:, 2:]
    J = (cameras[:, :2, :3] - x[:, :, None] * cameras[:, 2:3, :3]) / h[:, 2, None, None]      # (N, 2, 3)
    if np.any(radii):
        e = x - centres
        n = np.hypot(e[:, 0], e[:, 1])
        out = n > radii
        with np.errstate(divide="ignore", invalid="ignore"):
            k = np.where(out, 1.0 - radii / n, 0.0)
            w = np.where(out, radii / (n * n * n), 0.0)
        D = k[:, None, None] * np.eye(2) + w[:, None, None] * e[:, :, None] * e[:, None, :]
        J = D @ J
    return J.reshape(2 * N, 3)


def _looped_residuals(X, cameras, regions) -> np.ndarray:
    """r_i stacked (2N,) through the regions' closest points (a :class:`~tritools.model.regions.RegionStack`, or a
    sequence stacked here: each region's own ``closest_point``, stacked by kind); :data:`FAR_RESIDUAL` where a
    projection is at infinity."""
    Xh = np.append(X, 1.0)
    p = cameras @ Xh
    if np.any(np.abs(p[:, 2]) < 1e-300):
        return np.full(2 * len(regions), FAR_RESIDUAL)
    x = p[:, :2] / p[:, 2:]
    return (x - RegionStack.of(regions).closest(x)).reshape(-1)


def disc_shapes(regions) -> tuple | None:
    """(centres (N, 2), radii (N,)) where every region is a point (radius 0) or a filled disc
    (:attr:`~tritools.model.regions.Region.disc_radius`), else None."""
    radii = []
    for r in regions:
        rho = 0.0 if r.is_point else r.disc_radius
        if rho is None:
            return None
        radii.append(float(rho))
    return np.array([r.center for r in regions], float), np.array(radii)


def residual_function(cameras, regions) -> tuple:
    """(f(X) -> the stacked residuals (2N,), vectorised: whether f is one numpy expression) for these regions."""
    cameras = np.asarray(cameras, float)
    shapes = disc_shapes(regions)
    if shapes is None:
        stack = RegionStack.of(regions)
        return (lambda X: _looped_residuals(X, cameras, stack)), False
    return (lambda X: disc_residuals(X, cameras, *shapes)), True


def residual_jacobian(cameras, regions):
    """J(X) -> d r / d X (2N, 3) for point and disc regions (:func:`disc_jacobian`), else ``"2-point"`` (scipy's
    finite differences through the regions' ``closest_point``)."""
    cameras = np.asarray(cameras, float)
    shapes = disc_shapes(regions)
    if shapes is None:
        stack = RegionStack.of(regions)
        return lambda X: stacked_jacobian(X, cameras, stack)
    return lambda X: disc_jacobian(X, cameras, *shapes)


def stacked_jacobian(X, cameras: np.ndarray, stack: RegionStack) -> np.ndarray:
    """d r / d X (2N, 3) of the residuals through a :class:`~tritools.model.regions.RegionStack`: d x_i / d X of
    :func:`disc_jacobian` times :meth:`~tritools.model.regions.RegionStack.residual_derivatives` (I - the
    projection's derivative onto each region); zero where a projection is at infinity or the derivatives are not
    finite (the residuals are then constant or refused)."""
    N = len(cameras)
    h = cameras @ np.append(np.asarray(X, float), 1.0)
    if np.any(np.abs(h[:, 2]) < 1e-300):
        return np.zeros((2 * N, 3))
    x = h[:, :2] / h[:, 2:]
    if not np.all(np.isfinite(x)):
        return np.zeros((2 * N, 3))
    J = (cameras[:, :2, :3] - x[:, :, None] * cameras[:, 2:3, :3]) / h[:, 2, None, None]
    J = stack.residual_derivatives(x) @ J
    return np.where(np.isfinite(J), J, 0.0).reshape(2 * N, 3)


def gamma_discs(Xs: np.ndarray, cameras: np.ndarray, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """gamma (SPEC §1) of candidates Xs (m, 3) for point / disc regions, (m,): the projections of
    :func:`tritools.model.frame.project_world` (compensated where the plain sum cancels), d_i = max(0,
    |x_i - c_i| - rho_i); inf where a projection is at infinity or X is not finite (the rule of
    :func:`tritools.model.geometry.gamma_validated`, whose loop over the views this replaces for these regions)."""
    from .frame import project_world

    Xs = np.asarray(Xs, float)
    fin = np.isfinite(Xs).all(axis=1)
    with np.errstate(all="ignore"):
        u, _, ok = project_world(np.broadcast_to(cameras, (len(Xs),) + cameras.shape), np.where(fin[:, None], Xs, 0.0))
        e = u - centres
        d = np.hypot(e[..., 0], e[..., 1])
        if np.any(radii):
            d = np.maximum(d - radii, 0.0)
        out = np.sqrt(np.sum(d * d, axis=1) / (2 * cameras.shape[0]))
    return np.where(fin & ok & np.isfinite(out), out, np.inf)


def evaluations_floor(vectorised: bool) -> int:
    """The evaluations past the deadline always allowed, whatever the time (module docstring): a stacked evaluation
    costs microseconds, so :data:`MIN_EVALS_AFTER_DEADLINE` of them; a looped one only the start (its value: the
    estimate of last resort; 30 mixed views cost ~2 ms per evaluation, and an LM step needs four)."""
    return MIN_EVALS_AFTER_DEADLINE if vectorised else 1


def evaluations_after(n_views: int, vectorised: bool) -> int:
    """Evaluations allowed once the deadline has passed (module docstring): a vectorised evaluation counts as one
    region distance of :data:`VIEW_EVALS_AFTER_DEADLINE`; a looped one as ``n_views`` of
    :data:`LOOPED_VIEW_EVALS_AFTER_DEADLINE`."""
    if vectorised:
        return max(MIN_EVALS_AFTER_DEADLINE, VIEW_EVALS_AFTER_DEADLINE)
    return max(MIN_LOOPED_EVALS_AFTER_DEADLINE, LOOPED_VIEW_EVALS_AFTER_DEADLINE // max(1, n_views))


class RefinementStopped(Exception):
    """The refinement used up its evaluations after the deadline (:class:`EvaluationGuard`)."""


class EvaluationGuard:
    """Wraps the residual function: remembers the best iterate (least sum of squares) and raises
    :class:`RefinementStopped` once ``allowed`` evaluations were made after the active deadline passed."""

    def __init__(self, fun, allowed: int, floor: int | None = None, early: bool = False):
        """``early``: once it has an iterate, the floor does not apply (looped evaluations: each costs ~N closest
        points, and 4 of them at 100 views of mixed regions were ~10 ms past a 0.05 s limit); the vectorised
        ones keep their floor (cheap, and the trivial bound after a time limit needs them to converge)."""
        self.fun, self.allowed, self.early = fun, allowed, early
        self.floor = allowed if floor is None else min(floor, allowed)
        self.deadline = active_deadline()
        self.after = 0
        self.best_X, self.best_cost = None, np.inf

    def __call__(self, X) -> np.ndarray:
        if self.deadline is not None and self.deadline.expired:
            if self.after >= self.allowed or ((self.after >= self.floor or (self.early and self.best_X is not None))
                                              and self.deadline.overrun() > OVERRUN_SHARE_AFTER_DEADLINE):
                raise RefinementStopped
            self.after += 1
        r = self.fun(X)
        cost = float(r @ r)
        if cost < self.best_cost:                  # (nan never is)
            self.best_X, self.best_cost = np.array(X, float), cost
        return r
