"""sospoly.analysis.ascend_one: Newton ascent on the Lagrangian dual of a quadratic program with quadratic equalities
reaches the degree-2 SDP's value (checked against the same SDP written by hand in cvxpy and solved by Clarabel),
never exceeds the program's minimum (checked against scipy multi-start local minima), stops at a target, and the
bound reported at its multipliers (bound_at_one) is the rigorous one."""
import numpy as np
import pytest

from sospoly import DEFAULT_TOLERANCES
from sospoly.analysis import SparseQuadratics, ascend_one, bound_at_one, verify_quadratic_batch


def _program(rng, n, K):
    """f = |v - a|^2 (f0, f1, F2) and K random quadratic equalities with a common feasible point."""
    a = rng.normal(size=n) * 3.0
    x0 = rng.normal(size=n)                              # feasible by construction
    G2 = rng.normal(size=(K, n, n))
    G2 = (G2 + G2.transpose(0, 2, 1)) / 2
    g1 = rng.normal(size=(K, n))
    g0 = -(g1 @ x0 + np.einsum("i,kij,j->k", x0, G2, x0))
    return float(a @ a), -2.0 * a, np.eye(n), g0, g1, G2, x0


def _sdp_value(f0, f1, F2, g0, g1, G2):
    """max t s.t. [[L0 - t, L1^T / 2], [L1 / 2, L2]] PSD: the degree-2 SOS program, by hand in cvxpy + Clarabel."""
    cp = pytest.importorskip("cvxpy")
    K, n = g1.shape
    lam, t = cp.Variable(K), cp.Variable()
    L0 = f0 + g0 @ lam
    L1 = f1 + g1.T @ lam
    L2 = F2 + sum(lam[k] * G2[k] for k in range(K))
    top = cp.hstack([cp.reshape(L0 - t, (1, 1), order="C"), cp.reshape(L1 / 2, (1, n), order="C")])
    M = cp.vstack([top, cp.hstack([cp.reshape(L1 / 2, (n, 1), order="C"), L2])])
    prob = cp.Problem(cp.Maximize(t), [(M + M.T) / 2 >> 0])
    prob.solve(solver=cp.CLARABEL)
    return float(t.value) if prob.status == "optimal" else None


def _local_min(f0, f1, F2, g0, g1, G2, rng, starts=12):
    from scipy.optimize import minimize

    best = np.inf
    cons = [{"type": "eq", "fun": (lambda v, k=k: g0[k] + g1[k] @ v + v @ G2[k] @ v),
             "jac": (lambda v, k=k: g1[k] + 2 * G2[k] @ v)} for k in range(len(g0))]
    for _ in range(starts):
        r = minimize(lambda v: f0 + f1 @ v + v @ F2 @ v, rng.normal(size=len(f1)) * 3, jac=lambda v: f1 + 2 * F2 @ v,
                     constraints=cons, method="SLSQP", options={"ftol": 1e-12, "maxiter": 500})
        if r.success and max(abs(c["fun"](r.x)) for c in cons) < 1e-9:
            best = min(best, r.fun)
    return best


def _sparse(G2):
    return SparseQuadratics.from_dense(G2[None])


@pytest.mark.parametrize("seed", range(8))
def test_ascent_reaches_the_sdp_value_and_stays_below_the_minimum(seed):
    rng = np.random.default_rng(seed)
    n, K = int(rng.integers(3, 7)), int(rng.integers(1, 4))
    f0, f1, F2, g0, g1, G2, x0 = _program(rng, n, K)
    found = ascend_one(f0, f1, F2, g0, g1, _sparse(G2), np.zeros(K))
    assert found is not None
    lam, d = found
    fx0 = float(f0 + f1 @ x0 + x0 @ x0)
    radius = float(np.linalg.norm(x0 - (-f1 / 2))) + float(np.linalg.norm(-f1 / 2))   # |v*| <= |a| + |x0 - a|
    out = bound_at_one(f0, f1, F2, g0, g1, _sparse(G2), lam, fx0, DEFAULT_TOLERANCES, radius)
    lb = float(out.lower_bound[0])
    assert np.isfinite(lb) and lb <= d + 1e-9 * max(1.0, abs(d))
    sdp = _sdp_value(f0, f1, F2, g0, g1, G2)
    if sdp is not None:
        assert lb <= sdp + 1e-6 * max(1.0, abs(sdp))                  # no bound above the SDP's optimum ...
        assert lb >= sdp - 1e-4 * max(1.0, abs(sdp))                  # ... and (nearly) its value
    assert lb <= _local_min(f0, f1, F2, g0, g1, G2, rng) + 1e-9      # below every feasible value found


def test_ascent_stops_at_the_target_and_improves_on_the_kkt_multipliers():
    rng = np.random.default_rng(11)
    f0, f1, F2, g0, g1, G2, x0 = _program(rng, 6, 3)
    full = ascend_one(f0, f1, F2, g0, g1, _sparse(G2), np.zeros(3))
    target = 0.5 * full[1]
    part = ascend_one(f0, f1, F2, g0, g1, _sparse(G2), np.zeros(3), target=target)
    assert part[1] >= target and part[1] <= full[1] + 1e-9 * abs(full[1])
    # from the KKT multipliers of a feasible (not optimal) point the verification's own bound is weaker
    ver = verify_quadratic_batch(np.array([f0]), f1[None], F2[None], g0[None], g1[None], G2[None], x0[None])
    kkt = ver.lower_bound[0]
    climbed = ascend_one(f0, f1, F2, g0, g1, _sparse(G2), ver.multipliers[0])
    assert not np.isfinite(kkt) or climbed[1] >= kkt - 1e-9 * max(1.0, abs(kkt))
    sdp = _sdp_value(f0, f1, F2, g0, g1, G2)
    # a hard case (the dual's supremum on the boundary of the PD set): both climbs stay below the SDP's value
    assert max(climbed[1], full[1]) <= sdp + 1e-6 * abs(sdp) and climbed[1] >= 0.9 * sdp


def test_no_positive_definite_start_gives_none():
    n = 3
    F2 = -np.eye(n)                                   # concave f: L2 = -I + lam G2 with G2 = 0 is never PD
    G2 = np.zeros((1, n, n))
    assert ascend_one(0.0, np.zeros(n), F2, np.zeros(1), np.ones((1, n)), _sparse(G2), np.zeros(1)) is None


def _counted_ascent(monkeypatch, *args, **kwargs):
    """ascend_one(*args, **kwargs) and the Newton steps it took."""
    import sospoly.analysis.lagrangian as lagrangian

    calls = []
    step = lagrangian._newton_step
    monkeypatch.setattr(lagrangian, "_newton_step", lambda *a: calls.append(1) or step(*a))
    out = lagrangian.ascend_one(*args, **kwargs)
    monkeypatch.undo()
    return out, len(calls)


@pytest.mark.parametrize("seed", range(8))
def test_a_target_out_of_reach_ends_the_ascent_early_and_one_within_reach_is_reached(seed, monkeypatch):
    """out_of_reach: with a target 3% above the SDP's value (checked by cvxpy + Clarabel) the ascent gives up
    after its first centred weights instead of climbing to the end; with one 0.1% below the value it never gives
    up (it reaches the target)."""
    rng = np.random.default_rng(seed)
    n, K = int(rng.integers(3, 7)), int(rng.integers(1, 4))
    f0, f1, F2, g0, g1, G2, _ = _program(rng, n, K)
    sdp = _sdp_value(f0, f1, F2, g0, g1, G2)
    if sdp is None:
        pytest.skip("the hand-written SDP did not solve")
    args = (f0, f1, F2, g0, g1, _sparse(G2), np.zeros(K))
    full, n_full = _counted_ascent(monkeypatch, *args)
    high = sdp + 0.03 * max(1.0, abs(sdp))
    part, n_part = _counted_ascent(monkeypatch, *args, target=high)
    assert part[1] < high and part[1] <= full[1] + 1e-9 * max(1.0, abs(full[1]))
    assert n_part < n_full                               # it gave up before the climb's end
    low = sdp - 1e-3 * max(1.0, abs(sdp))
    if full[1] >= low:                                   # (a hard case may end below it without a target too)
        reached = ascend_one(*args, target=low)
        assert reached[1] >= low


def test_a_start_stalled_at_the_boundary_is_retried_from_zero():
    """A robust five-view subset holding a wrong match (tests/data/ascent_stalled_start.npz: f = |v|^2 in the normalised
    frame, the ten epipolar equalities, the KKT multipliers of its candidate): the ascent from the KKT start alone
    stalls below the target; ascend_one's second start from lambda = 0 reaches it, the rigorous bound at its
    multipliers (bound_at_one, on the ball of the candidate's norm) passes it too and stays below the degree-2 SDP's
    value (cvxpy + Clarabel, by hand) and the candidate's cost."""
    import pathlib

    import sospoly.analysis.lagrangian as lagrangian

    d = np.load(pathlib.Path(__file__).parent / "data" / "ascent_stalled_start.npz")
    g0, g1, G2, lam0, v, target = d["g0"], d["g1"], d["G2"], d["lam0"], d["v"], float(d["target"])
    n = len(v)
    f0, f1, F2 = 0.0, np.zeros(n), np.eye(n)
    data = (F2, f1, f0, g0, g1, G2)
    alone = lagrangian._ascend_from(data, lam0, target, lagrangian.ASCENT_MAX_ITER)
    assert alone is None or alone[1] < target                            # the stall this guards against
    found = ascend_one(f0, f1, F2, g0, g1, _sparse(G2), lam0, target=target)
    assert found is not None and found[1] >= target
    radius = float(np.linalg.norm(v))
    lb = float(bound_at_one(f0, f1, F2, g0, g1, _sparse(G2), found[0], radius ** 2, DEFAULT_TOLERANCES,
                            radius).lower_bound[0])
    assert target * (1 - 1e-6) <= lb <= float(v @ v)
    sdp = _sdp_value(f0, f1, F2, g0, g1, G2)
    if sdp is not None:
        assert lb <= sdp + 1e-6 * max(1.0, abs(sdp))
