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
"solved" for infeasible c.  The bisection stops when
``c_hi - c_lo <= bisection_abs + bisection_rel * max(1, |c_lo|)``; the lower bound
reported is ``c_lo``, the last level with a checked certificate.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..certificates.psatz import Multiplier, PsatzProblem
from ..lowering.conic import ConicProblem, GramForm
from .compiled_solve import CompiledPsatz
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
                 tolerances: Tolerances = DEFAULT_TOLERANCES, deadline=None):
        if psatz.multiplier != Multiplier.FREE:
            raise ValueError("CompiledGevp needs a Psatz problem built with multiplier='free'")
        self.psatz = psatz
        self.backend = backend
        self.tolerances = as_tolerances(tolerances)
        self.deadline = deadline
        self.compiled = CompiledPsatz(psatz.structure, form)

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
            return SolveStatus.FEASIBLE, ps
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
        return _bisect(c_lo, c_hi, max_search, tol, steps, test)
    except _OutOfTime:
        lo, best = found
        return GevpResult(SolveStatus.TIME_LIMIT, lo, (lo, c_hi), tuple(steps), best,
                          "time limit reached during the bisection" + (f" (best certified level {lo:.10g})"
                                                                       if lo is not None else ""))


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
        return GevpResult(SolveStatus.INFEASIBLE, None, (None, c_hi), tuple(steps), None,
                          "no feasible level c found: no certificate at this degree")
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
        if hi is None:
            return GevpResult(SolveStatus.UNBOUNDED, np.inf, (lo, np.inf), tuple(steps), best,
                              "every tested level is certified: the constraint set may be empty")
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
