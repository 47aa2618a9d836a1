"""Nothing starts past a deadline that a later stage has to pay for (issue #22: "no call exceeds its time limit by
more than 10%"): the interior-point backend does not set up a program once the deadline has passed, and a plan of
SDP steps has its answer of last resort (the local estimate) before its first step, not after the step the deadline
cut."""
import numpy as np
import scipy.sparse as sp

import tritools
from sospoly.budget import Deadline
from sospoly.lowering.conic import Cone, ConicProblem
from sospoly.solvers import backends
from sospoly.solvers.backends import IpmBackend, RawStatus
from sospoly.algebra.svec import svec
from tritools.scene import uncertain_problem


def _lmin(n=4, seed=0):
    """max c s.t. A - c I >= 0 in conic form (one PSD block: the IPM's program)."""
    M = np.random.default_rng(seed).standard_normal((n, n))
    A = svec(np.eye(n))[:, None]
    return ConicProblem(np.array([-1.0]), sp.csc_matrix(A), svec(M @ M.T), (Cone("psd", n * (n + 1) // 2, n),), 1, ())


def test_the_ipm_is_not_set_up_past_the_deadline(monkeypatch):
    import sospoly.solvers.ipm as ipm

    def boom(*a, **k):
        raise AssertionError("the IPM was set up past the deadline")
    monkeypatch.setattr(ipm, "ipm_solve_sparse", boom)
    monkeypatch.setattr(ipm, "ipm_solve_batch", boom)
    sol = IpmBackend().solve(_lmin(), deadline=Deadline.after(0.0))
    assert sol.attempts[0].label == backends.IPM_LABEL
    assert sol.attempts[0].raw_status == RawStatus.TIME_LIMIT and sol.attempts[0].iterations == 0
    assert all(a.raw_status == RawStatus.TIME_LIMIT for a in sol.attempts)
    assert sol.x is None


def test_the_ipm_still_solves_before_the_deadline():
    prob = _lmin()
    sol = IpmBackend().solve(prob, deadline=Deadline.after(60.0))
    M = np.random.default_rng(0).standard_normal((4, 4))
    assert sol.raw_status == RawStatus.SOLVED
    assert abs(-sol.primal_objective - np.linalg.eigvalsh(M @ M.T)[0]) < 1e-6


def test_sdp_steps_have_the_local_estimate_before_the_first_step():
    P, R, _ = uncertain_problem(6, seed=1, kinds="mixed")
    res = tritools.triangulate(P, R, path="sdp")
    keys = list(res.timings)
    assert "local" in keys and "build" in keys
    assert keys.index("local") < keys.index("build")        # computed before the step's problem was built
    assert res.X is not None and res.gamma_ub is not None
