"""Lower bounds from Positivstellensatz programs: one SDP (fixed q) or the GEVP bisection (free q).

:func:`solve_psatz` takes a :class:`~sospoly.certificates.psatz.PsatzProblem` (or a compiled
instance), compiles its structure (:mod:`sospoly.solvers.compiled_solve`), solves it within the
deadline, and returns a :class:`~sospoly.solvers.solve.LowerBound` whose ``lower_bound`` is c* only
when the solver said solved *and* the certificate passed the a-posteriori checks.
"""
from __future__ import annotations

from ..budget import Deadline
from ..certificates.psatz import Multiplier, PsatzProblem, psatz_structure
from ..lowering.compiled import CompiledInstance
from ..lowering.conic import GramForm
from ..status import SolveStatus
from ..tolerances import DEFAULT_TOLERANCES, Tolerances, as_tolerances
from .compiled_solve import CompiledPsatz
from .gevp import CompiledGevp, GevpResult, bisect
from .psatz_claims import PsatzBound
from .solve import LowerBound, ProgramSolution

__all__ = ["solve_psatz"]


def _fixed_twin(psatz: PsatzProblem) -> PsatzProblem:
    """The fixed-q program (the paper's q, unit trace up to scaling) on the same data: its c* is a feasible
    level of the free-q GEVP."""
    from ..certificates.psatz import default_q

    st = psatz.structure
    q = default_q(st.gens, st.degree, st.slots.degrees[0])
    return PsatzProblem(psatz_structure(st.slots, st.degree, st.shape, q), psatz.theta, psatz.f, psatz.eq,
                        psatz.ineq)


def solve_psatz(psatz, *, backend=None, form: GramForm = GramForm.IMAGE,
                tolerances: Tolerances = DEFAULT_TOLERANCES, c_hi: float | None = None,
                fixed_hint: ProgramSolution | None = None, deadline: Deadline | None = None,
                prove: bool = True) -> LowerBound:
    """Solve a Positivstellensatz program: one SDP (fixed q) or the GEVP bisection (free q).

    For the free multiplier the bracket starts from the fixed-q SDP's c* (solved here unless
    ``fixed_hint`` gives it) and from ``c_hi`` (f at a feasible point), if known.  ``psatz`` may
    also be a :class:`sospoly.lowering.compiled.CompiledInstance` (a compiled structure filled with
    one instance's numbers): then only its conic data is solved.  ``deadline`` bounds the wall time
    (status ``TIME_LIMIT``; a bisection then reports its best certified level).

    ``prove`` (default True): ``lower_bound`` is proven for every v (:mod:`sospoly.solvers.psatz_claims`; the
    fixed-q c* lowered by m <= 1e-7 of the scale, or INACCURATE / UNPROVEN when only a weaker bound or none is
    proven; every accepted bisection step proven, :mod:`sospoly.solvers.gevp`), and the solver's c* is
    ``relaxation``.  ``prove=False``: the numerical c* (checked a posteriori, not proven) as ``lower_bound``, for
    callers that prove it themselves (:func:`sospoly.minimize`, tritools).  "The set is empty" (UNBOUNDED,
    ``lower_bound = inf``) is claimed only with a proven ray, in both modes.
    """
    tolerances = as_tolerances(tolerances)
    if isinstance(psatz, CompiledInstance):
        if not isinstance(psatz.compiled, CompiledPsatz):
            raise TypeError("psatz: an instance of a structure that was only lowered (LoweredPsatz); bind it "
                            "with a sospoly.CompiledPsatz (sospoly.compile_psatz) to solve it")
        return psatz.compiled.solve_theta(psatz.theta, backend=backend, tolerances=tolerances, problem=psatz.problem,
                                          deadline=deadline, prove=prove)
    slots = psatz.structure.slots
    if not slots.n_eq and not slots.n_ineq and slots.degrees[0] > 0 and slots.degrees[0] % 2:   # (f = 0: degree -1)
        # f of odd degree on all of R^n is unbounded below, so no certificate exists at any degree.
        # The SDP is then only *weakly* infeasible (no Farkas certificate): solvers cannot detect it
        # and report numerical errors, so decide it exactly here.
        return LowerBound(SolveStatus.INFEASIBLE, None, None, None,
                          f"f has odd degree {slots.degrees[0]} and there are no constraints: f is unbounded below")
    if psatz.multiplier == Multiplier.FREE:
        c_lo = None
        if fixed_hint is None:
            fixed = _fixed_twin(psatz)
            fixed_hint = CompiledPsatz(fixed.structure, form).solve_theta(
                fixed.theta, backend=backend, tolerances=tolerances, deadline=deadline, prove=False).solution
        if fixed_hint is not None and fixed_hint.status == SolveStatus.OPTIMAL:
            c_lo = fixed_hint.objective
        g: GevpResult = bisect(CompiledGevp(psatz, backend, form, tolerances, deadline, prove=prove), c_lo, c_hi)
        top = max((s.c for s in g.steps if s.status.ok), default=None)
        return PsatzBound(g.status, g.lower_bound, g.solution, g.bracket, g.message, relaxation=top)
    return CompiledPsatz(psatz.structure, form).solve_theta(psatz.theta, backend=backend, tolerances=tolerances,
                                                            deadline=deadline, prove=prove)
