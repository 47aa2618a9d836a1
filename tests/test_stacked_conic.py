"""sospoly.solvers.stacked_conic: many small LP/SOCP blocks solved as block-diagonal stacks, against
closed forms; bad blocks isolated by bisection with their own certificates; bad input."""
import numpy as np
import pytest

from sospoly.solvers.stacked_conic import BlockStatus, StackedConicOptions, solve_stacked


def ball_blocks(rng, B):
    """min q'x s.t. ||x - c|| <= r (rows: s = (r, c - x) in SOC(4)); optimum q'c - r ||q||."""
    c = rng.normal(size=(B, 3)) * 10
    r = rng.uniform(0.1, 5, B)
    q = rng.normal(size=(B, 3))
    A = np.zeros((B, 4, 3))
    A[:, 1:, :] = np.eye(3)
    b = np.concatenate([r[:, None], c], axis=1)
    return q, A, b, np.einsum("bi,bi->b", q, c) - r * np.linalg.norm(q, axis=1)


def test_soc_blocks_match_closed_form():
    rng = np.random.default_rng(0)
    q, A, b, best = ball_blocks(rng, 500)
    sol = solve_stacked(q, A, b, 0, 0, (4,), StackedConicOptions(chunk=128))
    assert np.all(sol.status == BlockStatus.SOLVED)
    val = np.einsum("bi,bi->b", q, sol.x)
    assert np.allclose(val, best, atol=1e-7 * (1 + np.abs(best)))
    assert np.allclose(-np.einsum("bi,bi->b", b, sol.z), best, atol=1e-7 * (1 + np.abs(best)))   # dual value
    assert sol.solves == 4


def test_lp_blocks_with_equalities():
    """min q'x s.t. x_3 = e, l <= x <= u: optimum sum of q_k times the bound it prefers."""
    rng = np.random.default_rng(1)
    B = 200
    l, u = -rng.uniform(1, 2, (B, 3)), rng.uniform(1, 2, (B, 3))
    e = rng.uniform(-0.5, 0.5, B)
    q = rng.normal(size=(B, 3))
    A = np.zeros((B, 7, 3))
    A[:, 0, 2] = 1.0                                  # x_3 + s = e, s = 0
    A[:, 1:4] = -np.eye(3)                            # s = x - l >= 0
    A[:, 4:7] = np.eye(3)                             # s = u - x >= 0
    b = np.concatenate([e[:, None], -l, u], axis=1)
    sol = solve_stacked(q, A, b, 1, 6)
    best = np.where(q[:, :2] > 0, q[:, :2] * l[:, :2], q[:, :2] * u[:, :2]).sum(axis=1) + q[:, 2] * e
    assert np.all(sol.status == BlockStatus.SOLVED)
    assert np.allclose(np.einsum("bi,bi->b", q, sol.x), best, atol=1e-7)


def test_bad_blocks_are_isolated_with_certificates():
    rng = np.random.default_rng(2)
    q, A, b, best = ball_blocks(rng, 64)
    q, A, b = q.copy(), A.copy(), b.copy()
    b[10, 0] = -1.0                                   # radius -1: infeasible
    A[40, 0, 0] = -1.0                                # t = r + x_1: the cone opens along +x_1 ...
    q[40] = np.array([-1.0, 0.0, 0.0])                # ... and the objective runs along it: unbounded
    A[40, 0, 0], b[40, 0] = -2.0, 0.0
    sol = solve_stacked(q, A, b, 0, 0, (4,), StackedConicOptions(chunk=64))
    assert sol.status[10] == BlockStatus.INFEASIBLE
    z = sol.z[10]
    assert np.allclose(np.einsum("mi,m->i", A[10], z), 0.0, atol=1e-7) and b[10] @ z < 0    # Farkas
    assert sol.status[40] == BlockStatus.UNBOUNDED
    d = sol.x[40]
    s = -A[40] @ d
    assert q[40] @ d < 0 and s[0] >= np.linalg.norm(s[1:]) - 1e-7 * np.linalg.norm(d)      # a ray
    ok = np.setdiff1d(np.arange(64), [10, 40])
    assert np.all(sol.status[ok] == BlockStatus.SOLVED)
    assert np.allclose(np.einsum("bi,bi->b", q[ok], sol.x[ok]), best[ok], atol=1e-6 * (1 + np.abs(best[ok])))
    assert sol.solves > 1


def test_bad_input():
    q, A, b, _ = ball_blocks(np.random.default_rng(3), 3)
    with pytest.raises(ValueError, match="shapes"):
        solve_stacked(q[:, :2], A, b, 0, 0, (4,))
    with pytest.raises(ValueError, match="cone dimensions"):
        solve_stacked(q, A, b, 0, 0, (3,))
    with pytest.raises(ValueError, match="dimension >= 2"):
        solve_stacked(q, A, b, 3, 0, (1,))
    A2 = A.copy()
    A2[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        solve_stacked(q, A2, b, 0, 0, (4,))
    with pytest.raises(ValueError, match="chunk"):
        StackedConicOptions(chunk=0)
    with pytest.raises(ValueError, match="tol_feas"):
        StackedConicOptions(tol_feas=2.0)
