"""Issue #22, mixed uncertain regions on many views: Clarabel's fast chain (a first attempt without iterative
refinement, :data:`sospoly.solvers.CLARABEL_FAST_CHAIN`) for region and view-clique steps, and the rigorous
bound of compiled instances with inequalities.

References are independent of the certificates: tests/reference/regions.py (bounded least squares over X and
the regions' own parametrisations: an attained value, so an upper bound of gamma*), and a hand-made conic
program with a known optimum for the chain rule.
"""
from __future__ import annotations

import types

import numpy as np
import pytest
import scipy.sparse as sp

import tritools
from sospoly.solvers import CLARABEL_FAST_CHAIN, ClarabelBackend
from sospoly.solvers.backends import RawStatus
from tests.reference.regions import region_reference, spec_of
from tritools.scene import uncertain_problem

LARGE = dict(noise_px=16.0, size_px=16.0)     # regions as large as the noise: degree 2 rarely certifies


def reference(cams, regions, starts, seed=0) -> float:
    return region_reference(cams, [spec_of(r) for r in regions], starts, np.random.default_rng(seed))


def labels(res) -> list[str]:
    return [s.split(":")[0] for a in res.attempts for s in a.solver]


def assert_sound(res, cams, regs, X, scale=1.0):
    """gamma_LB below an attained value; a certificate attains it (to the certificate's tolerance)."""
    ref = reference(cams, regs, [X] + ([res.X] if res.X is not None else []))
    assert res.gamma_lb is not None and res.gamma_lb <= res.gamma_ub
    assert res.gamma_lb <= ref * (1 + 1e-9) + 1e-9 * scale
    if res.optimal:
        assert res.gamma_ub <= ref * (1 + 1e-6) + 1e-9 * scale
    return ref


# ----------------------------------------------------------------------------- the chain rule (sospoly)
class _Problem:
    """min -x1 - x2 s.t. [[1, x1], [x1, 1]] >= 0, 0 <= x2 <= 2 (optimum -3 at x = (1, 2))."""
    n_cols = 2
    q = np.array([-1.0, -1.0])
    A = sp.csc_matrix(np.array([[0.0, 0.0], [-np.sqrt(2), 0.0], [0.0, 0.0], [0.0, -1.0], [0.0, 1.0]]))
    b = np.array([1.0, 0.0, 1.0, 0.0, 2.0])
    n_rows = 5

    class _Cone:
        def __init__(self, kind, dim, size=None):
            self.kind, self.dim, self.size = kind, dim, size

    cones = (_Cone("psd", 3, 2), _Cone("nonneg", 2))


def test_fast_chain_ends_at_a_solved_first_attempt():
    sol = ClarabelBackend(retry_chain=CLARABEL_FAST_CHAIN).solve(_Problem())
    assert sol.raw_status == RawStatus.SOLVED and len(sol.attempts) == 1
    assert sol.attempts[0].label == "no-refinement"
    assert sol.primal_objective == pytest.approx(-3.0, abs=1e-6)


def test_fast_chain_goes_on_after_an_almost_solved_first_attempt(monkeypatch):
    # the provisional attempt's ALMOST_SOLVED is never final, even when inaccurate answers are accepted
    import dataclasses

    from sospoly import DEFAULT_TOLERANCES

    be = ClarabelBackend(dataclasses.replace(DEFAULT_TOLERANCES, accept_inaccurate=True),
                         retry_chain=CLARABEL_FAST_CHAIN)
    real = ClarabelBackend.solve_once

    def fake(self, problem, label="default", overrides=None, *args, **kw):
        sol, att = real(self, problem, label, overrides, *args, **kw)
        if label == "no-refinement":
            att = dataclasses.replace(att, raw_status=RawStatus.ALMOST_SOLVED)
        return sol, att

    monkeypatch.setattr(ClarabelBackend, "solve_once", fake)
    sol = be.solve(_Problem())
    assert [a.label for a in sol.attempts] == ["no-refinement", "default"]
    assert sol.raw_status == RawStatus.SOLVED and sol.primal_objective == pytest.approx(-3.0, abs=1e-6)


def test_provisional_almost_solved_kept_when_the_refined_attempt_runs_out_of_time(monkeypatch):
    # review 18: the refined attempt ran to the time limit and the step reported no bound at all; the provisional
    # ALMOST_SOLVED answer (accepted by the caller's check) is returned then, for the caller to make rigorous
    import dataclasses

    from sospoly import DEFAULT_TOLERANCES

    real = ClarabelBackend.solve_once

    def fake(self, problem, label="default", overrides=None, *args, **kw):
        sol, att = real(self, problem, label, overrides, *args, **kw)
        if label == "no-refinement":
            return sol, dataclasses.replace(att, raw_status=RawStatus.ALMOST_SOLVED)
        return sol, dataclasses.replace(att, raw_status=RawStatus.TIME_LIMIT)

    monkeypatch.setattr(ClarabelBackend, "solve_once", fake)
    tol = dataclasses.replace(DEFAULT_TOLERANCES, accept_inaccurate=True)
    sol = ClarabelBackend(tol, retry_chain=CLARABEL_FAST_CHAIN).solve(_Problem())
    assert [a.label for a in sol.attempts] == ["no-refinement", "default"]
    assert sol.raw_status == RawStatus.ALMOST_SOLVED and sol.primal_objective == pytest.approx(-3.0, abs=1e-6)
    refused = ClarabelBackend(tol, retry_chain=CLARABEL_FAST_CHAIN).solve(_Problem(), accept=lambda x, z: False)
    assert refused.raw_status == RawStatus.TIME_LIMIT           # not accepted by the check: nothing kept
    strict = ClarabelBackend(retry_chain=CLARABEL_FAST_CHAIN).solve(_Problem())
    assert strict.raw_status == RawStatus.TIME_LIMIT            # without accept_inaccurate: nothing kept


@pytest.mark.parametrize("refined", [RawStatus.FAILED, RawStatus.ALMOST_SOLVED])
def test_provisional_almost_solved_kept_when_no_refined_attempt_is_accepted(monkeypatch, refined):
    # review 3 of wave 18: refined attempts that all fail, or end almost solved and rejected by the check, lost the
    # accepted provisional answer (FAILED, or the last rejected iterate); the accepted one is returned
    import dataclasses

    from sospoly import DEFAULT_TOLERANCES

    real = ClarabelBackend.solve_once

    def fake(self, problem, label="default", overrides=None, *args, **kw):
        sol, att = real(self, problem, label, overrides, *args, **kw)
        if label != "no-refinement":
            sol = types.SimpleNamespace(x=np.asarray(sol.x) + 1.0, z=np.asarray(sol.z), obj_val=99.0,
                                        obj_val_dual=99.0)
        return sol, dataclasses.replace(att, raw_status=RawStatus.ALMOST_SOLVED if label == "no-refinement"
                                        else refined)

    monkeypatch.setattr(ClarabelBackend, "solve_once", fake)
    tol = dataclasses.replace(DEFAULT_TOLERANCES, accept_inaccurate=True)
    first = {}

    def accept(x, z):                       # accepts only the provisional iterate (the first one seen)
        first.setdefault("x", np.array(x))
        return np.array_equal(x, first["x"])

    sol = ClarabelBackend(tol, retry_chain=CLARABEL_FAST_CHAIN).solve(_Problem(), accept=accept)
    assert len(sol.attempts) == len(CLARABEL_FAST_CHAIN)               # every refined attempt ran
    assert sol.raw_status == RawStatus.ALMOST_SOLVED
    assert np.array_equal(sol.x, first["x"]) and sol.primal_objective == pytest.approx(-3.0, abs=1e-6)
    refused = ClarabelBackend(tol, retry_chain=CLARABEL_FAST_CHAIN).solve(_Problem(), accept=lambda x, z: False)
    assert not np.array_equal(refused.x, first["x"])                    # nothing accepted: nothing kept


def test_a_dual_infeasible_attempt_whose_ray_fails_the_check_goes_on_to_the_next_settings(monkeypatch):
    # review 3 of wave 18: Clarabel's unchecked DualInfeasible ended the chain (numerical_error, no bound) where a
    # later attempt solves; a ray that fails the check is a numerical failure now (and a valid one still ends it)
    import dataclasses

    real = ClarabelBackend.solve_once

    def fake(ray):
        def solve_once(self, problem, label="default", overrides=None, *args, **kw):
            sol, att = real(self, problem, label, overrides, *args, **kw)
            if label != "default":
                return sol, att
            bad = types.SimpleNamespace(x=np.asarray(ray, float), z=np.zeros(problem.n_rows), obj_val=np.nan,
                                        obj_val_dual=np.nan)
            return bad, dataclasses.replace(att, raw_status=RawStatus.DUAL_INFEASIBLE)
        return solve_once

    monkeypatch.setattr(ClarabelBackend, "solve_once", fake([1.0, 1.0]))      # leaves the PSD cone: no ray
    sol = ClarabelBackend().solve(_Problem())
    assert [a.label for a in sol.attempts][:2] == ["default", "qdldl"]
    assert sol.raw_status == RawStatus.SOLVED and sol.primal_objective == pytest.approx(-3.0, abs=1e-6)
    monkeypatch.setattr(ClarabelBackend, "solve_once", real)

    class Unbounded(_Problem):                  # without x2 <= 2: x2 grows without bound, a genuine ray
        A, b, n_rows = _Problem.A[:4], _Problem.b[:4], 4
        cones = (_Problem._Cone("psd", 3, 2), _Problem._Cone("nonneg", 1))

    sol = ClarabelBackend().solve(Unbounded())
    assert sol.raw_status == RawStatus.DUAL_INFEASIBLE and [a.label for a in sol.attempts] == ["default"]


# ----------------------------------------------------------------------------- triangulation
def test_point_regions_keep_the_default_chain():
    cams, regs, X = uncertain_problem(6, 0, kinds="point", noise_px=1.0)
    res = tritools.triangulate(cams, regs, "corollary1", delta=2, path="sdp")
    assert "no-refinement" not in labels(res)
    assert_sound(res, cams, regs, X)
    assert res.optimal


@pytest.mark.parametrize("n_views, seed", [(4, 1), pytest.param(8, 0, marks=pytest.mark.slow),
                                           pytest.param(16, 0, marks=pytest.mark.slow)])
def test_views_steps_run_the_fast_chain_and_stay_sound(n_views, seed):
    cams, regs, X = uncertain_problem(n_views, seed, **LARGE)
    res = tritools.triangulate(cams, regs)
    assert_sound(res, cams, regs, X)
    views = [a for a in res.attempts if a.sparsity == "views"]
    assert views or res.delta == 2                                    # degree 2 certifies, or a views step ran
    assert all(a.solver[0].startswith("no-refinement") for a in views if a.solver)    # views: the fast chain
    assert not any(s.startswith("no-refinement") for a in res.attempts if a.sparsity == "dense" for s in a.solver)
    assert res.optimal


@pytest.mark.parametrize("scale", [1e-3, 1e6])
def test_mixed_regions_under_pixel_rescaling(scale):
    # pixels scaled by s (P -> diag(s, s, 1) P, regions by the same similarity): gamma scales by s; the bounds
    # stay below the rescaled reference, and a certificate reports s times the unscaled value
    cams, regs, X = uncertain_problem(4, 1, **LARGE)
    base = tritools.triangulate(cams, regs)
    S = np.diag([scale, scale, 1.0])
    cams_s = np.einsum("ij,njk->nik", S, cams)
    regs_s = [r.similarity(scale, np.zeros(2)) for r in regs]
    res = tritools.triangulate(cams_s, regs_s)
    ref = assert_sound(res, cams_s, regs_s, X, scale)
    assert ref == pytest.approx(scale * reference(cams, regs, [X]), rel=1e-6)
    assert base.optimal and res.optimal
    assert res.gamma_ub == pytest.approx(scale * base.gamma_ub, rel=1e-6)


def test_an_unchecked_infeasibility_does_not_override_the_accepted_provisional_answer(monkeypatch):
    # review 4: a refined attempt's PrimalInfeasible (never checked) discarded the provisional answer that the
    # caller's check had accepted -- a feasible iterate; the accepted answer is returned
    import dataclasses

    from sospoly import DEFAULT_TOLERANCES

    real = ClarabelBackend.solve_once

    def fake(self, problem, label="default", overrides=None, *args, **kw):
        sol, att = real(self, problem, label, overrides, *args, **kw)
        status = RawStatus.ALMOST_SOLVED if label == "no-refinement" else RawStatus.PRIMAL_INFEASIBLE
        return sol, dataclasses.replace(att, raw_status=status)

    monkeypatch.setattr(ClarabelBackend, "solve_once", fake)
    tol = dataclasses.replace(DEFAULT_TOLERANCES, accept_inaccurate=True)
    sol = ClarabelBackend(tol, retry_chain=CLARABEL_FAST_CHAIN).solve(_Problem())
    assert sol.raw_status == RawStatus.ALMOST_SOLVED and sol.primal_objective == pytest.approx(-3.0, abs=1e-6)
    plain = ClarabelBackend(tol, retry_chain=CLARABEL_FAST_CHAIN).solve(_Problem(), accept=lambda x, z: False)
    assert plain.raw_status == RawStatus.PRIMAL_INFEASIBLE          # nothing accepted: the solver's word stands
