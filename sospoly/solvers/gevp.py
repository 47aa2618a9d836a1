"""Free-multiplier Positivstellensatz as a GEVP solved by bisection on c (SPEC §5).

With q a free SOS (trace(Gram(q)) = 1), c multiplies decision variables, so
``max c`` is a generalised eigenvalue problem.  For fixed c the constraints are
an LMI feasibility problem; the program is lowered **once** with c as a
parameter (``A(c) = A0 + c A1``, ``b(c) = b0 + c b1``) and only c changes
between steps.

Bracket: ``c_lo`` must be *verified* feasible (by default the fixed-q SDP's c*,
which is feasible here too after scaling q to unit trace, or a descending search);
``c_hi`` is any upper bound of the true minimum (f at a feasible point) or is
found by doubling.  A level c is accepted as feasible only when the solver says
solved **and** the certificate passes :func:`sospoly.solvers.solve.check_certificate`
(Gram eigenvalues and equality residuals with the margins of
:class:`~sospoly.tolerances.Tolerances`): near-degenerate q lets solvers report
"solved" for infeasible c.

**Proven steps** (``prove=True``, the default).  A Gram defect eps accepted by any margin
lowers the level by up to eps ||b(v*)||^2 / q(v*) at a minimiser v*, and the bisection climbs
to the edge of whatever margin it is given: at (x - 1e4)^2 + y^2 the margin 1e-9 max|G| let it
"certify" 8.39e6 for a minimum of 0 (review 26a F2).  So a step is accepted only when its
certificate is also *proven* within the gap tolerance of c by
:func:`sospoly.solvers.psatz_claims.proven_bound` (the shifted certificate of
:func:`sospoly.analysis.proof.global_psatz_bound`: m <= 1e-7 max(max|coef f|, |c|), the Gram
matrices projected onto the exact identities, every rounding absorbed, q >= lambda_min(Q) > 0
proven; or the rigorous bound on the constraints' or a sublevel set's box); the bound reported is
the proven level of the highest accepted step (at most the gap tolerance below the bracket's
lower end, the highest accepted level).  ``prove=False``
keeps the numerical acceptance alone (for callers that prove the bound themselves).

The bisection stops when ``c_hi - c_lo <= bisection_abs + bisection_rel * max(1, |c_lo|)``.
A step that fails (a solver failure, a failed check or proof) is treated as an upper end,
which keeps the lower bound valid; but when *no* level was accepted, INFEASIBLE ("no
certificate at this degree") is reported only when every tested level was proven infeasible
by a checked Farkas certificate, NUMERICAL_ERROR otherwise (review 26a F7: 40 solver failures
on x^2 + 1e12 were reported as infeasibility).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..certificates.psatz import Multiplier, PsatzProblem
from ..lowering.conic import ConicProblem, GramForm
from .compiled_solve import CompiledPsatz
from .psatz_claims import as_certificate_data, data_scale, proven_bound
from .solve import ProgramSolution, check_certificate, solve_conic
from ..status import SolveStatus
from ..tolerances import DEFAULT_TOLERANCES, Tolerances, as_tolerances

__all__ = ["GevpStep", "GevpResult", "CompiledGevp", "bisect"]


@dataclass(frozen=True)
class GevpStep:
    c: float
    status: SolveStatus


@dataclass(frozen=True)
class GevpResult:
    """Outcome of :func:`bisect`: the last certified level ``lower_bound``, the final ``bracket``, every tested
    step and the certificate at the lower end."""
    status: SolveStatus
    lower_bound: float | None
    bracket: tuple
    steps: tuple
    solution: ProgramSolution | None = None   # the certificate at lower_bound
    message: str = ""


class CompiledGevp:
    """A free-q Psatz program lowered once (its level c is a parameter of the compiled structure);
    ``feasible(c)`` solves one LMI."""

    def __init__(self, psatz: PsatzProblem, backend=None, form: GramForm = GramForm.IMAGE,
                 tolerances: Tolerances = DEFAULT_TOLERANCES, deadline=None, prove: bool = True):
        if psatz.multiplier != Multiplier.FREE:
            raise ValueError("CompiledGevp needs a Psatz problem built with multiplier='free'")
        self.psatz = psatz
        self.backend = backend
        self.tolerances = as_tolerances(tolerances)
        self.deadline = deadline
        self.prove = bool(prove)
        self.compiled = CompiledPsatz(psatz.structure, form)
        self.proven: dict = {}          # accepted level c -> the level proven from its certificate (c - m)
        self.negative_margin: set = set()   # levels whose solved margin t was negative (evidence of no certificate)
        self._data = as_certificate_data(psatz)
        self.scale = data_scale(self._data)

    def _acceptance(self, inst: ConicProblem, c: float):
        """Accept level c only if the original certificate checks out (see module docstring).

        The solve maximises a margin t with G_u - t I >= 0; we require t and
        lambda_min(G_u) >= -gevp_psd_margin * max(1, max|G_u|) (100x stricter than the
        general PSD margin: above c*, lambda_min(G_u) ~ -(c - c*)/2, so this keeps the
        accepted level within solver accuracy of c*; it cannot be 0 exactly because Gram
        bases with monomials outside the Newton polytope force singular Grams), re-check
        every Gram matrix of the *original* problem at x, and reject
        certificates whose q is nearly singular relative to u's PSD error: u + eps ||b||^2
        is SOS with eps = max(0, -lambda_min(G_u)), and with q >= lambda_q ||b_q||^2 the
        bound degrades by about eps / lambda_q, which must stay below the bisection
        tolerance (this rejects the "solved" answers at infeasible levels where q
        collapses onto the minimisers: six-hump camel at degree 8, lambda_q ~ 6e-6).
        """
        tol = self.tolerances
        limit = tol.bisection_abs + tol.bisection_rel * max(1.0, abs(c))

        def check(x, _mins):
            ok, mins, resid, msg = check_certificate(inst, x[:-1], tol)
            if not ok:
                return False, msg
            eps = max(0.0, -mins.get("u", 0.0))
            G = inst.gram_matrices(x[:-1])["u"]
            strict = tol.gevp_psd_margin * max(1.0, float(np.max(np.abs(G))))
            if x[-1] < -strict:             # the solved program's largest margin is negative: no certificate here
                self.negative_margin.add(float(c))
            if x[-1] < -strict or eps > strict:
                # above c*, lambda_min(G_u) ~ -(c - c*)/2: the general PSD margin would let the
                # accepted level creep ~1e-7 above c*; this one keeps it at solver accuracy
                return False, f"margin t = {x[-1]:.3g}, lambda_min(G_u) = {-eps:.3g} (limit {strict:.2g})"
            lam_q = mins.get("q", 0.0)
            if lam_q <= 0.0 or eps / lam_q > limit:
                return False, f"ill-conditioned q: lambda_min(q)={lam_q:.3g}, PSD error of u {eps:.3g}"
            check.mins, check.resid = mins, resid
            return True, ""
        check.mins, check.resid = {}, np.nan
        return check

    def feasible(self, c: float) -> tuple[SolveStatus, ProgramSolution]:
        inst = self.compiled.problem_from_theta(self.psatz.theta, c=float(c))
        aug = inst.with_margin("u")
        check = self._acceptance(inst, c)
        status, sol, _, _, msg = solve_conic(aug, self.backend, self.tolerances, feasibility=False,
                                             extra_check=check, retry=False, deadline=self.deadline)
        prog = self.psatz.program
        if status.ok:
            x = sol.x[:-1]
            ps = ProgramSolution(SolveStatus.FEASIBLE, float(c), x[: prog.n_vars].copy(), inst.gram_matrices(x),
                                 inst.dual_matrices(sol.z[:-1]), check.mins, check.resid, sol.attempts,
                                 prog.n_lmivar(), sol.seconds, msg)
            if not self.prove:
                self.proven[float(c)] = float(c)
                return SolveStatus.FEASIBLE, ps
            near = self.tolerances.gap_tolerance_one(float(c), self.scale)
            best, _, why = proven_bound(self._data, ps, float(c), self.scale, near, self.deadline)
            if best >= float(c) - near:
                self.proven[float(c)] = float(best)
                return SolveStatus.FEASIBLE, ps
            status, msg = SolveStatus.UNPROVEN, f"level {float(c):.10g} not proven: {why}"
        ps = ProgramSolution(status, None, None, attempts=sol.attempts, n_lmivar=prog.n_lmivar(),
                             seconds=sol.seconds, message=msg)
        return status, ps


def bisect(compiled: CompiledGevp, c_lo: float | None = None, c_hi: float | None = None,
           max_search: int = 40) -> GevpResult:
    """Maximise c by bisection (see module docstring)."""
    tol = compiled.tolerances
    steps: list[GevpStep] = []
    found: list = [None, None]          # the highest certified level and its certificate

    def test(c):
        st, ps = compiled.feasible(c)
        steps.append(GevpStep(float(c), st))
        if st == SolveStatus.TIME_LIMIT:
            raise _OutOfTime
        if st.ok and (found[0] is None or c > found[0]):
            found[:] = [float(c), ps]
        return st.ok, ps

    try:
        res = _bisect(c_lo, c_hi, max_search, tol, steps, test)
    except _OutOfTime:
        lo, best = found
        lo = None if lo is None else compiled.proven.get(lo, lo)
        return GevpResult(SolveStatus.TIME_LIMIT, lo, (lo, c_hi), tuple(steps), best,
                          "time limit reached during the bisection" + (f" (best certified level {lo:.10g})"
                                                                       if lo is not None else ""))
    return _claimed(res, compiled, c_hi)


class _OutOfTime(Exception):
    pass


def _bisect(c_lo, c_hi, max_search, tol, steps, test) -> GevpResult:
    best = None

    # ---- a verified feasible lower end
    lo = None
    start = 0.0 if c_lo is None else float(c_lo)
    width = max(1.0, abs(start))
    for k in range(max_search):
        c = start - (0.0 if k == 0 else width * 2.0 ** (k - 1))
        ok, ps = test(c)
        if ok:
            lo, best = c, ps
            break
    if lo is None:
        if steps and all(s.status == SolveStatus.INFEASIBLE for s in steps):
            return GevpResult(SolveStatus.INFEASIBLE, None, (None, c_hi), tuple(steps), None,
                              f"every tested level down to {steps[-1].c:.6g} is infeasible (checked Farkas "
                              "certificates): no certificate at this degree")
        failed = sorted({s.status.value for s in steps if s.status != SolveStatus.INFEASIBLE})
        return GevpResult(SolveStatus.NUMERICAL_ERROR, None, (None, c_hi), tuple(steps), None,
                          f"no level c was certified, and {sum(s.status != SolveStatus.INFEASIBLE for s in steps)} of "
                          f"{len(steps)} steps failed numerically ({', '.join(failed)}): not a proof of infeasibility")
    # ---- an upper end
    if c_hi is None or c_hi <= lo:
        hi = None
        step = max(1.0, abs(lo))
        for k in range(max_search):
            c = lo + step * 2.0 ** k
            ok, ps = test(c)
            if ok:
                lo, best = c, ps
            else:
                hi = c
                break
        if hi is None:      # (a finite proven level, not inf: an empty set is not proven by finitely many levels)
            return GevpResult(SolveStatus.UNBOUNDED, lo, (lo, np.inf), tuple(steps), best,
                              f"every tested level up to {lo:.6g} is certified: the constraint set may be empty")
    else:
        hi = float(c_hi)
    # ---- bisection
    n = 0
    while hi - lo > tol.bisection_abs + tol.bisection_rel * max(1.0, abs(lo)) and n < tol.bisection_max_steps:
        mid = 0.5 * (lo + hi)
        ok, ps = test(mid)
        if ok:
            lo, best = mid, ps
        else:
            hi = mid
        n += 1
    return GevpResult(SolveStatus.OPTIMAL, lo, (lo, hi), tuple(steps), best, "")


def _claimed(res: GevpResult, compiled, c_hi) -> GevpResult:
    """The result with the level proven from the accepted step's certificate (``compiled.proven``), and OPTIMAL only
    where the upper end says so: f at a feasible point, or a level the solver found infeasible (a Farkas
    certificate, or a solved program whose largest margin t is negative).  An upper end where the solver failed,
    its answer failed the other checks (review 26c F1: a Gram defect or an ill-conditioned q is no evidence that no
    certificate exists) or the proof did not hold says nothing of c*, so there the
    lowest infeasible level (or ``c_hi``) must lie within the gap tolerance of the proven bound; else INACCURATE (the
    bound is proven, its optimality is not).  An upward search that certified every level it tried is INACCURATE at
    the proven level, not UNBOUNDED ("empty" needs a proven ray)."""
    lo = res.lower_bound
    if lo is None or not np.isfinite(lo):
        return res
    proven = compiled.proven.get(lo, lo)
    status, msg = res.status, res.message
    if status == SolveStatus.UNBOUNDED and compiled.prove:
        # every tested level certified, up to a finite one: no proven ray, so no "empty set" (review 26c F2)
        return GevpResult(SolveStatus.INACCURATE, proven, res.bracket, res.steps, res.solution,
                          f"{msg} (not proven: no ray); the bound {proven:.10g} is proven")
    hi = res.bracket[1]
    end = next((s.status for s in reversed(res.steps) if s.c == hi), None)
    if status == SolveStatus.OPTIMAL and end in _FAILED:
        tops = [s.c for s in res.steps if s.status == SolveStatus.INFEASIBLE or
                (s.status == SolveStatus.CHECK_FAILED and s.c in getattr(compiled, "negative_margin", ()))]
        top = min(tops + ([float(c_hi)] if c_hi is not None else []), default=np.inf)
        if not top - proven <= compiled.tolerances.gap_tolerance_one(top if np.isfinite(top) else 0.0,
                                                                      compiled.scale):
            status = SolveStatus.INACCURATE
            msg = (f"the bracket's upper end {hi:.10g} is a failed step ({end.value}), not an infeasible level, and "
                   f"no infeasible level lies within the gap tolerance: the bound {proven:.10g} is proven, its "
                   "optimality is not")
    return GevpResult(status, proven, res.bracket, res.steps, res.solution, msg)


#: step statuses that are failures, not evidence that the level is infeasible
_FAILED = (SolveStatus.UNPROVEN, SolveStatus.NUMERICAL_ERROR, SolveStatus.INACCURATE, SolveStatus.NOT_SOLVED,
           SolveStatus.CHECK_FAILED)
