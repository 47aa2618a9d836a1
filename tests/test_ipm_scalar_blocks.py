"""One Gram block beside scalar blocks (Corollary 1 at delta = 2 with regions: the regions' constant inequality
multipliers are 1 x 1 blocks) goes to the interior-point method when it is large enough and an "almost solved"
answer is taken (sospoly.solvers.backends.AutoBackend, issue #22 wave 8).  Its stalled iterate is taken only when
it meets Clarabel's own "almost solved" rule (``ipm_almost_solved``); the references here are independent:
Clarabel on the same conic program, and a multi-start bounded least squares over X for the optimum.
"""
import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest

import sospoly
import tritools
from sospoly.solvers import backends
from sospoly.solvers.backends import (AUTO_IPM_MIN_COST_SCALARS, CLARABEL_SPLIT_CHAIN, IPM_ALMOST_GAP_SHARE,
                                      AutoBackend, ClarabelBackend, RawStatus, ipm_almost_solved)
from sospoly.solvers.ipm import ipm_solve_sparse, layout_of
from tritools.scene import uncertain_problem

INACCURATE = dataclasses.replace(sospoly.DEFAULT_TOLERANCES, accept_inaccurate=True)
GAP = INACCURATE.gap_rel / IPM_ALMOST_GAP_SHARE      # the IPM's gap when its stalled iterate is taken


def _reference_gamma(cams, regions, X0):
    """An attained gamma (>= the optimum): the manyview benchmark's multi-start least squares over X with exact
    distances to the regions (benchmarks/manyview.py:reference_gamma), 12 starts."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    import manyview

    return manyview.reference_gamma(cams, regions, X0, starts=12)


@pytest.fixture(scope="module")
def degree2_run():
    """A 14-view mixed-region problem at delta = 2, with the conic programs AutoBackend was given."""
    seen = []
    orig = AutoBackend.solve

    def recording(self, problem, *a, **k):
        seen.append((problem, self.clarabel.tolerances))
        return orig(self, problem, *a, **k)

    cams, regs, X = uncertain_problem(14, 5, kinds="mixed", noise_px=1.0, size_px=0.5)   # verification fails
    AutoBackend.solve = recording
    try:
        res = tritools.triangulate(cams, regs, "corollary1", delta=2)
    finally:
        AutoBackend.solve = orig
    return cams, regs, X, res, seen


def _scalar_program(seen):
    progs = [p for p, _ in seen if sum(1 for n in layout_of(p.cones).sizes if n > 1) == 1
             and len(layout_of(p.cones).sizes) > 1]
    assert progs, "the degree-2 program with regions has one Gram block beside scalar blocks"
    return progs[0]


def test_degree2_with_regions_takes_the_ipm_and_stays_sound(degree2_run):
    cams, regs, X, res, seen = degree2_run
    sdp = [a for a in res.attempts if a.step == "sdp"]
    assert sdp and sdp[0].solver[0].startswith("ipm:"), sdp
    prob = _scalar_program(seen)
    m, sizes = prob.n_cols, layout_of(prob.cones).sizes
    assert sum(m * n ** 3 for n in sizes) >= AUTO_IPM_MIN_COST_SCALARS
    ref = _reference_gamma(cams, regs, X)
    assert res.gamma_lb is not None and res.gamma_lb <= ref * (1 + 1e-9) + 1e-12
    assert res.gamma_ub is not None and res.gamma_lb <= res.gamma_ub
    # the same program through Clarabel alone: same certified outcome, same bound to the almost-solved rule
    clar = tritools.triangulate(cams, regs, "corollary1", delta=2, backend="clarabel")
    assert clar.optimal == res.optimal
    assert abs(clar.gamma_lb - res.gamma_lb) <= INACCURATE.gap_rel * clar.gamma_lb


def test_ipm_objective_matches_clarabel_on_the_program(degree2_run):
    prob = _scalar_program(degree2_run[4])
    ipm = AutoBackend(INACCURATE, clarabel_chain=CLARABEL_SPLIT_CHAIN).solve(prob)
    ref = ClarabelBackend(sospoly.DEFAULT_TOLERANCES).solve(prob)
    assert ipm.attempts[0].label == "ipm" and ipm.raw_status in (RawStatus.SOLVED, RawStatus.ALMOST_SOLVED)
    assert ref.raw_status == RawStatus.SOLVED
    scale = max(1.0, abs(ref.primal_objective))
    assert abs(ipm.primal_objective - ref.primal_objective) <= GAP * scale


def test_almost_solved_rule_rejects_a_poor_iterate(degree2_run):
    prob = _scalar_program(degree2_run[4])
    res = ipm_solve_sparse(prob.A, prob.b, prob.q, prob.cones, INACCURATE)
    assert ipm_almost_solved(prob, res, INACCURATE)
    poor = dataclasses.replace(res, x=res.x * (1 + 1e-4))          # primal residual ~1e-4
    assert not ipm_almost_solved(prob, poor, INACCURATE)
    scale = np.maximum(1, np.abs(res.primal_objective))
    wide = dataclasses.replace(res, dual_objective=res.primal_objective - 3 * GAP * scale)
    assert not ipm_almost_solved(prob, wide, INACCURATE)
    # the gap allowed follows the certificate rule's gap_rel
    assert ipm_almost_solved(prob, wide, dataclasses.replace(INACCURATE, gap_rel=10 * INACCURATE.gap_rel))
    nan = dataclasses.replace(res, x=np.full_like(res.x, np.nan))
    assert not ipm_almost_solved(prob, nan, INACCURATE)


def test_without_accept_inaccurate_or_after_an_ipm_attempt_clarabel_solves(degree2_run):
    prob = _scalar_program(degree2_run[4])
    strict = AutoBackend(sospoly.DEFAULT_TOLERANCES, clarabel_chain=CLARABEL_SPLIT_CHAIN).solve(prob)
    assert strict.attempts[0].label != "ipm"
    # skip holds labels, as solve_psatz passes the attempts it already made
    again = AutoBackend(INACCURATE, clarabel_chain=CLARABEL_SPLIT_CHAIN, skip=("ipm",)).solve(prob)
    assert all(a.label != "ipm" for a in again.attempts)
    assert again.raw_status in (RawStatus.SOLVED, RawStatus.ALMOST_SOLVED)


def test_small_programs_beside_scalars_stay_with_clarabel(monkeypatch):
    """Below AUTO_IPM_MIN_COST_SCALARS (6 views: Clarabel 0.01 s, the IPM 0.03 s) Clarabel answers."""
    seen = []
    orig = backends.IpmBackend.solve

    def spy(self, *a, **k):
        seen.append(1)
        return orig(self, *a, **k)

    monkeypatch.setattr(backends.IpmBackend, "solve", spy)
    cams, regs, X = uncertain_problem(6, 1, kinds="mixed", noise_px=1.0, size_px=0.5)
    res = tritools.triangulate(cams, regs, "corollary1", delta=2)
    assert not seen
    sdp = [a for a in res.attempts if a.step == "sdp"]
    assert sdp and not sdp[0].solver[0].startswith("ipm")
