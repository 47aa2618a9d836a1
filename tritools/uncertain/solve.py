"""Bound problems of a stack of per-view uncertainty sets, solved as stacked conic programs.

For M problems of one structure and their objectives (6 coordinates, then the lower and upper
depth in each view) every (problem, objective) pair is one block of
:func:`sospoly.solvers.stacked_conic.solve_stacked`, in the normalised variables
``eta = (X - X0) / sigma``.  A first pass adds the box ``|eta_j| <= BOX`` (so every block is
bounded and the stacks rarely need bisecting); blocks whose box is active, infeasible or failed
are solved again without it, which yields the solver's own certificates: an unbounded ray or a
Farkas dual.  The box rows' multipliers are never used in a bound (:mod:`.rigour` uses the
region rows only).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sospoly.solvers import BlockStatus, StackedConicOptions, solve_stacked

from .sets import cone_layout, rows_of

__all__ = ["BOX", "Blocks", "solve_blocks", "objective_rows"]

#: half-width of the first pass's box, in units of sigma
BOX = 1e5


@dataclass(frozen=True)
class Blocks:
    """Per (problem, objective): ``status`` (M, K) BlockStatus, ``eta`` (M, K, 3) primal point (or ray),
    ``z`` (M, K, m) region-row multipliers on the *unscaled* rows of :func:`rows_of`, and the row
    layout ``(n_zero, n_nonneg, n_soc)``."""
    status: np.ndarray
    eta: np.ndarray
    z: np.ndarray
    layout: tuple
    solves: int


def objective_rows(depth_rows: np.ndarray) -> np.ndarray:
    """Target linear functions on xi = X - X0 (M, K, 3): +e_k (lower bound of X_k), -e_k (upper),
    then +q_i, -q_i for each view's depth row ``q_i`` (x part)."""
    M, N = depth_rows.shape[:2]
    E = np.eye(3)
    q = depth_rows[:, :, :3]
    out = [np.broadcast_to(E, (M, 3, 3)), np.broadcast_to(-E, (M, 3, 3))]
    out.append(np.stack([q, -q], axis=2).reshape(M, 2 * N, 3))
    return np.concatenate(out, axis=1)


def _problem_rows(R, blocks, X0, sigma):
    """Stacked rows (M, m, 4) in eta~ with their unit-norm scaling (returned as ``scale`` (M, m): the
    solver row is ``scale * row``); order: zero rows, nonneg rows, SOC blocks (3 rows each)."""
    zs, ns, ss = [], [], []
    for i, blk in enumerate(blocks):
        z, n, s = rows_of(blk, R[:, i])
        zs.append(z)
        ns.append(n)
        ss.append(s)
    rows = np.concatenate(zs + ns + ss, axis=1)                    # (M, m, 4) on X~
    shift = np.einsum("mrj,mj->mr", rows[:, :, :3].astype(np.longdouble), X0.astype(np.longdouble))
    shift = (shift + rows[:, :, 3]).astype(float)          # extended precision: georeferenced X0 cancel here
    eta_rows = np.concatenate([rows[:, :, :3] * sigma[:, None, None], shift[:, :, None]], axis=2)
    n0, n1, n2 = cone_layout(blocks)
    with np.errstate(over="ignore", invalid="ignore"):                  # a disc too small for floats: FAILED
        norms = np.linalg.norm(eta_rows, axis=2)
    scale = 1.0 / np.where(norms > 0, norms, 1.0)
    if n2:
        soc = norms[:, n0 + n1:].reshape(len(R), n2, 3).max(axis=2)
        scale[:, n0 + n1:] = np.repeat(1.0 / np.where(soc > 0, soc, 1.0), 3, axis=1)
    return eta_rows * scale[:, :, None], scale, (n0, n1, n2)


def _box_rows(M):
    E = np.eye(3)
    rows = np.concatenate([np.concatenate([-E, np.full((3, 1), BOX)], axis=1),
                           np.concatenate([E, np.full((3, 1), BOX)], axis=1)])
    return np.broadcast_to(rows, (M, 6, 4))


def _run(rows, q, layout, boxed, options):
    """Solve the blocks (M*K) for rows (M, m, 4) and unit objectives q (M, K, 3).  A problem whose rows or
    objectives are not finite (a disc whose D^-1 overflows: radius 1e-160, review 31b F2) gets FAILED blocks and
    NaN points, and the others are solved (the stacked solver refuses a non-finite stack as a whole)."""
    finite = np.all(np.isfinite(rows), axis=(1, 2)) & np.all(np.isfinite(q), axis=(1, 2))
    if np.all(finite):
        return _run_finite(rows, q, layout, boxed, options)
    M, K = q.shape[:2]
    status = np.full((M, K), BlockStatus.FAILED, dtype=int)        # (the stacked solver's statuses are ints)
    eta, z, zbox = (np.full((M, K, n), np.nan) for n in (3, rows.shape[1], 6))
    solves = 0
    if np.any(finite):
        status[finite], eta[finite], z[finite], zbox[finite], solves = \
            _run_finite(rows[finite], q[finite], layout, boxed, options)
    return status, eta, z, zbox, solves


def _run_finite(rows, q, layout, boxed, options):
    """:func:`_run` on finite data."""
    M, K = q.shape[:2]
    n0, n1, n2 = layout
    if boxed:
        rows = np.concatenate([rows[:, :n0 + n1], _box_rows(M), rows[:, n0 + n1:]], axis=1)
        n1 = n1 + 6
    m = rows.shape[1]
    A = np.broadcast_to(-rows[:, None, :, :3], (M, K, m, 3)).reshape(M * K, m, 3)
    b = np.broadcast_to(rows[:, None, :, 3], (M, K, m)).reshape(M * K, m)
    sol = solve_stacked(q.reshape(M * K, 3), A, b, n0, n1, (3,) * n2, options)
    z = sol.z.reshape(M, K, m)
    if boxed:
        zbox = z[:, :, n0 + n1 - 6:n0 + n1]
        z = np.concatenate([z[:, :, :n0 + n1 - 6], z[:, :, n0 + n1:]], axis=2)
    else:
        zbox = np.zeros((M, K, 6))
    return sol.status.reshape(M, K), sol.x.reshape(M, K, 3), z, zbox, sol.solves


#: a ray d (unit max-norm) is accepted when every cone residual is below this and ``q.d <= -RAY_DESCENT``
RAY_TOL = 1e-7
RAY_DESCENT = 1e-6


def _is_ray(rows, q, d, layout) -> np.ndarray:
    """Check the solver's unboundedness certificates: ``d`` is a recession direction of S (every row's
    linear part maps it into its cone, to RAY_TOL on the unit-norm rows) along which ``q'd < 0``."""
    n0, n1, n2 = layout
    with np.errstate(invalid="ignore", divide="ignore"):
        d = d / np.max(np.abs(d), axis=1, keepdims=True)
        v = np.einsum("prj,pj->pr", rows[:, :, :3], d)
        ok = np.all(np.isfinite(v), axis=1)
        ok &= np.all(np.abs(v[:, :n0]) <= RAY_TOL, axis=1) & np.all(v[:, n0:n0 + n1] >= -RAY_TOL, axis=1)
        if n2:
            soc = v[:, n0 + n1:].reshape(len(d), n2, 3)
            ok &= np.all(soc[:, :, 0] + RAY_TOL >= np.linalg.norm(soc[:, :, 1:], axis=2), axis=1)
        ok &= np.einsum("pj,pj->p", q, d) <= -RAY_DESCENT * np.linalg.norm(q, axis=1)
    return ok


def solve_blocks(R, blocks, X0, sigma, targets, options: StackedConicOptions | None = None) -> Blocks:
    """Solve every (problem, target) bound problem: R (M, N, 3, 4) exact signed cameras, X0 (M, 3),
    sigma (M,), targets (M, K, 3) linear functions of xi to minimise."""
    rows, scale, layout = _problem_rows(R, blocks, X0, sigma)
    q = targets * sigma[:, None, None]
    q = q / np.linalg.norm(q, axis=2, keepdims=True)
    status, eta, z, zbox, solves = _run(rows, q, layout, True, options)
    box_active = (np.max(np.abs(eta), axis=2) > 0.5 * BOX) | (np.max(np.abs(zbox), axis=2) > 1e-9)
    redo = (status != BlockStatus.SOLVED) | box_active
    if np.any(redo):
        pm, ko = np.nonzero(redo)
        st2, eta2, z2, _, s2 = _run(rows[pm], q[pm, ko][:, None], layout, False, options)
        st2 = st2[:, 0]
        ray = st2 == BlockStatus.UNBOUNDED
        st2[ray & ~_is_ray(rows[pm], q[pm, ko], eta2[:, 0], layout)] = BlockStatus.FAILED
        status[pm, ko], eta[pm, ko], z[pm, ko] = st2, eta2[:, 0], z2[:, 0]
        solves += s2
    return Blocks(status, eta, z * scale[:, None, :], layout, solves)
