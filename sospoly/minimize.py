"""User entry points: :func:`minimize` (certified polynomial optimisation) and :func:`is_sos`.

``minimize(f, eq, ineq)`` returns a :class:`MinimizeResult`:

* ``lower_bound`` -- a lower bound of min f on {g = 0, h >= 0} proven from a checked Positivstellensatz
  certificate (strategy step 2: the PSD defect and the identity residual of the returned certificate
  accounted for on a box holding a minimiser, or for every v by the shifted certificate);
* ``minimizers`` / ``upper_bound`` -- extracted points (Gram kernel, moment matrices, clique moments
  for sparse certificates), polished locally, kept when feasible (by value, and near the set:
  :func:`~sospoly.analysis.candidates.value_shift` within the gap tolerance), sorted by f; ``upper_bound`` is f
  at the best one;
* ``optimal`` -- ``Tolerances.certified(lower_bound, upper_bound, scale)`` with ``scale`` the largest
  coefficient of the balanced f expanded at the origin or at the minimiser, the smaller (strategy steps 1 and
  8: the problem's own scale, ``result.scale``): a certificate of global optimality of ``minimizers[0]``.  A
  lower bound above the upper bound within the tolerance is reported equal to it; beyond it: ``INCONSISTENT``.

The default strategy (each step recorded in ``attempts``):

1. **Scaling** (:mod:`sospoly.scaling`). The variables are scaled by powers of two that balance the
   coefficients' magnitudes (v = 2^k w: M(s x, s y) becomes the Motzkin polynomial), then f and every
   constraint are divided by a power of two near their largest coefficient.  Every step is exact in
   floating point, so the scaled program *is* the caller's program: its certificate is one of the
   caller's problem, points map back exactly, and the tolerances act at the problem's own scale (the
   balanced objective's largest coefficient, ``scale``).  Bounds and points are reported in the
   caller's units; ``upper_bound`` is the caller's f at the reported point.
2. **A proven bound.** The solver's c* is reported only as far as it is proven
   (:mod:`sospoly.analysis.proof`): on a box that holds a minimiser -- ``radius``, or the box the
   constraints imply -- with the certificate's defects subtracted (:mod:`sospoly.analysis.rigor`), and
   for every v through the shifted certificate (level lowered by a margin of 1e-10..1e-7 of the scale, then
   1e-6..1e-1 where none is proven, a weaker bound; Gram matrices shifted, projected and checked PSD with every
   rounding bounded); the larger proven bound
   is reported.  A multiplier q counts only where it is proven positive (a constant, 1 + even positive
   terms, a free q whose Gram matrix is positive definite, or another fixed q whose minimum is proven
   positive, :mod:`sospoly.analysis.q_floor`).  Nothing proven: status
   ``unproven_bound``, no lower bound, the relaxation's value in the message.  An "almost solved"
   iterate that passes the a-posteriori checks is used the same way (its bound, when proven, is valid).
3. **Degrees.** ``degree`` given: that degree only.  Otherwise delta_min, delta_min + 2, ... up to
   ``max_degree`` (default delta_min + 4), stopping at the first certified degree.
4. **Sparsity** (``sparsity="auto"``): a correlative-sparsity certificate (cliques of a chordal
   extension of the variables' interaction graph; never weaker than the dense degree-2 certificate:
   a dense degree-2 block beside the cliques when it is small and can add strength -- a linear
   equality, a constant inequality or a non-constant user q; otherwise its Gram matrix has the
   cliques' chordal pattern and splits into the clique blocks, Agler et al. 1988) when that graph is
   not complete; when it does not certify and the dense program is small (Gram side <=
   ``DENSE_AUTO_MAX_SIDE``) and fits the budget, the dense certificate of the same degree next (at
   degree 2, where it gives the same bound, only at the last degree).  A complete graph: dense.
   ``"none"``, ``"correlative"``, ``"term"`` and ``"newton"`` force a choice; ``result.sparsity`` says
   which certificate gave the result.  Before the dense certificate ``"auto"`` tries the cheapest
   term-sparsity level when it has under 3/4 of the dense Gram entries, and for an unconstrained f the
   Newton-polytope basis when it is smaller (benchmarks/sparsity_suite.py measures the choice).
   ``"term"`` walks the term-sparsity hierarchy (:mod:`sospoly.certificates.term_hierarchy`) cheapest
   level first, up to the level whose bound is the dense one for unconstrained programs;
   ``result.sparsity`` names the level (``"term:block:1"``...).
5. **Multiplier** (``multiplier="auto"``): at each degree q = 1 first (Putinar's certificate, the
   strongest on compact sets: Floudas' test 4.10 is certified at degree 8), then, when that does not
   certify and the degree allows it, the paper's q = (1 + ||v||^2)^k (Reznick-type, for unconstrained
   positive polynomials that are not SOS, e.g. Motzkin).  ``"fixed"``, ``"putinar"``, ``"free"``
   or a user q force one.
6. **Numerical failures.** A solve that ends inaccurate, with a failed certificate check or a solver
   error is retried in the kernel form and with cvxpy's back-end (unless ``form`` / ``backend`` were
   given) before the step is given up.  The first back-end is ``"auto"`` for one Gram block and
   Clarabel for several (clique or term blocks: its sparse factorisation keeps them apart).
7. **Budget.** Every program is sized before it is built (:mod:`sospoly.budget`); one that does not fit is
   skipped (``budget_exceeded``); the call stops at ``budget.time_limit`` (``time_limit``, the best bounds so far).
8. **Re-centring** (:mod:`sospoly.recentre`). The decision is made at the smaller of the scales of f at the
   origin and at the minimiser (coefficients that cancel there: (v - 1000)^4 - 3 (v - 1000)^2 + 1), with f valued
   exactly at the points; where the minimiser's scale is ``CANCELLATION_BITS`` smaller, the program translated
   exactly to the minimiser is solved too, again at a better point whose scale is smaller still (at most
   ``RECENTRE_ROUNDS`` translations); the better result is kept, with the larger proven lower bound and the best
   point of all the solves, decided at the smallest of their scales.
"""
from __future__ import annotations

import dataclasses
import math
import numbers
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .algebra.polynomial import Polynomial
from .analysis.recession import unbounded_result
from .analysis.candidates import candidates_of, dedupe_points, feasibility_violation, feasible_points
from .analysis.candidates import support_of, value_shift_of
from .analysis.moments import moment_matrices_of
from .budget import Budget, BudgetExceeded, TimeLimitReached, as_budget, deadline_scope
from .analysis.proof import unsolved_claim
from .certificates.psatz import Multiplier, PsatzProblem, as_multiplier, build_psatz, checked_inputs
from .certificates.shape import MINIMIZE_SPARSITIES, Sparsity, low_block_helps
from .certificates.sparsity import correlative_sparsity
from .certificates.term_hierarchy import (cheap_term_level, newton_smaller, parse_term_kind, term_level_shape,
                                         term_levels)
from .lowering.conic import GramForm
from .solvers.backends import cvxpy_available, get_backend
from .recentre import in_callers_units
from .scaling import ScaledProgram, lifted, scaled_program, uncapped, used_gens
from .solvers.lower_bound import solve_psatz
from .solvers.solve import LowerBound, ProgramSolution
from .sos_check import SOSResult, is_sos
from .status import SolveStatus
from .tolerances import Tolerances, as_tolerances

__all__ = ["MinimizeResult", "SOSResult", "SolveAttempt", "LowerBound", "minimize", "solve_psatz", "is_sos",
           "feasibility_violation", "candidates_of", "DENSE_AUTO_MAX_SIDE"]

#: ``sparsity="auto"`` falls back from a sparse certificate that does not certify to the dense one of the same
#: degree while the dense Gram matrix is at most this large.
DENSE_AUTO_MAX_SIDE = 120
#: a program whose retry chain ended without a solved answer is solved once more for an "almost solved" iterate (used
#: through the proven bound only) when the chain took at most this many seconds.
ITERATE_MAX_SECONDS = 2.0
#: a certificate that could not be proven is solved again on the exactly reduced basis while its Gram side is at most
#: this (the re-solve costs as much again).
REDUCED_RETRY_MAX_SIDE = 60
#: the dense degree-2 block beside clique blocks is added while it stays this small (its side is n + 1).
LOW_BLOCK_MAX_SIDE = 61
_NUMERICAL = (SolveStatus.NUMERICAL_ERROR, SolveStatus.INACCURATE, SolveStatus.CHECK_FAILED)


@dataclass(frozen=True)
class SolveAttempt:
    """One solve of the strategy.  ``status`` and ``lower_bound`` are the solver's: the relaxation's value c*, not
    proven (it may lie above the minimum; the result's ``lower_bound`` is the proven one, review 32b L1)."""
    degree: int
    multiplier: str
    sparsity: str
    form: str
    backend: str
    status: str
    lower_bound: float | None
    seconds: float
    message: str = ""


@dataclass(frozen=True)
class MinimizeResult:
    """Outcome of :func:`minimize` (see the module docstring for every field's meaning)."""
    status: SolveStatus
    lower_bound: float | None
    upper_bound: float | None
    minimizers: tuple
    optimal: bool
    n_lmivar: int
    degree: int
    multiplier: str
    gens: tuple
    bracket: tuple | None = None
    solution: ProgramSolution | None = None
    seconds: float = 0.0
    message: str = ""
    candidates: tuple = ()
    sparsity: str = "dense"
    attempts: tuple = ()
    scale: float = 1.0
    moment_matrices: tuple = ()     # MomentMatrix per Gram block of u (.basis, .matrix; sospoly.analysis.moments)

    @property
    def gap(self) -> float | None:
        if self.lower_bound is None or self.upper_bound is None:
            return None
        return self.upper_bound - self.lower_bound

    def __str__(self) -> str:
        return (f"MinimizeResult(status={self.status.value}, lower={self.lower_bound}, upper={self.upper_bound}, "
                f"optimal={self.optimal}, degree={self.degree}, n_lmivar={self.n_lmivar}, sparsity={self.sparsity})")


# ----------------------------------------------------------------------------- strategy
def _choose_sparsity(sparsity, f, eq, ineq, degree: int, multiplier="auto", last: bool = True
                     ) -> list[tuple[str, int | None]]:
    """The (sparsity kind, low degree of a dense block) steps for ``sparsity`` at ``degree`` (see the
    module docstring).  The dense degree-2 block only where it can add strength
    (:func:`~sospoly.certificates.shape.low_block_helps`): elsewhere a Gram block of side n + 1 for nothing.  By
    the same argument the dense degree-2 certificate gives the correlative one's bound there, so
    after a correlative degree-2 step it is tried only at the ``last`` degree (for its minimisers:
    Gram-kernel extraction separates two minimisers that degree-1 clique moments cannot)."""
    from .algebra.basis import sigma

    sparsity = Sparsity.parse(sparsity, allowed=MINIMIZE_SPARSITIES)
    n = len(f.gens)
    low = 2 if degree > 2 and n + 1 <= LOW_BLOCK_MAX_SIDE and low_block_helps(eq, ineq, multiplier) else None
    if sparsity == "correlative":
        return [("correlative", low)]
    supports = (support_of(f), [support_of(g) for g in eq], [support_of(h) for h in ineq])
    if sparsity == "term":                 # the TSSOS hierarchy, cheapest level first (certificates.term_hierarchy)
        return [(k, None) for k in term_levels(*supports, degree)]
    if sparsity != Sparsity.AUTO:              # the steps' kinds are plain strings ("none": the dense one)
        return [("none" if sparsity == Sparsity.DENSE else sparsity.value, None)]
    if isinstance(multiplier, str) and multiplier == "free":
        return [("none", None)]                # a free q needs the dense certificate (review 18: auto raised)
    cs = correlative_sparsity(n, *supports)
    steps = [] if cs.is_dense else [("correlative", low)]
    if cs.is_dense or (sigma(n, degree // 2) <= DENSE_AUTO_MAX_SIDE and
                       (degree > 2 or last or low_block_helps(eq, ineq, multiplier))):
        # before the dense certificate (q = 1 only): the cheapest term-sparsity level when clearly smaller, and
        # for an unconstrained f the Newton-polytope basis when smaller (the dense bound for q = 1)
        q1 = isinstance(multiplier, str) and multiplier in ("auto", "putinar") and \
            sigma(n, degree // 2) <= DENSE_AUTO_MAX_SIDE
        term = cheap_term_level(*supports, degree) if q1 else None
        steps += [(term, None)] if term else []
        if q1 and not eq and not ineq and newton_smaller(supports[0], degree):
            steps.append(("newton", None))
        steps.append(("none", None))
    return steps


def _shape_with_q(kind, f, eq, ineq, degree: int, multiplier, max_gram_side: int):
    """``kind``, or for term sparsity and the Newton polytope with a non-constant user multiplier q the
    shape built on the support of u = q (f - c) (supp(q f) and supp(q)): ``build_psatz`` builds
    those shapes from supp(f), whose basis cannot hold q f (Motzkin, q = 1 + x^2 + y^2, degree 8:
    infeasible on the 4 monomials of N(f)/2, certified at 0 on the 9 of N(q f)/2)."""
    if (kind != "newton" and parse_term_kind(kind) is None) or \
            not (isinstance(multiplier, Polynomial) and multiplier.degree > 0):
        return kind
    from .certificates.shape import newton_shape

    n = len(f.gens)
    qs, fs = support_of(multiplier.with_gens(f.gens)), support_of(f)
    if kind == "newton":
        return kind if eq or ineq else newton_shape(fs, degree, q_support=qs, max_gram_side=max_gram_side)
    u_support = np.unique(np.vstack([(qs[:, None, :] + fs[None, :, :]).reshape(-1, n), qs]), axis=0)
    return term_level_shape(u_support, [support_of(g) for g in eq], [support_of(h) for h in ineq], degree, kind,
                            max_gram_side=max_gram_side)


def _multipliers(multiplier, degree: int, deg_f: int, dense: bool) -> list:
    if multiplier != "auto":
        return [as_multiplier(multiplier)]
    out = [Multiplier.PUTINAR]
    if dense and (degree - max(deg_f, 0)) // 2 >= 1:
        out.append(Multiplier.FIXED)
    return out


def _name_of(multiplier) -> str:
    if isinstance(multiplier, Multiplier):
        return multiplier.value
    return "given"


def _retry_chain(form, backend, blocks: int = 1) -> list:
    """(Gram form, back-end) pairs tried in turn.  A certificate of several Gram blocks (clique or
    term sparsity) goes to Clarabel first: its sparse KKT factorisation keeps the blocks apart,
    where the interior-point method of the ``"auto"`` back-end forms a dense Schur complement over
    all decision columns (generalised Rosenbrock, n = 200: 0.3 s against 18 s)."""
    forms = [GramForm(form)] if form is not None else [GramForm.IMAGE, GramForm.KERNEL]
    backends = [backend] if backend is not None else ["clarabel" if blocks > 1 else "auto"] + (
        ["cvxpy"] if cvxpy_available() else [])
    return [(fm, be) for be in backends for fm in forms]


def minimize(f: Polynomial | float, eq: Sequence[Polynomial | float] = (), ineq: Sequence[Polynomial | float] = (),
             degree: int | None = None, multiplier: Multiplier | Polynomial | str | float = "auto", *,
             sparsity: Sparsity | str = "auto", low_degree: int | None = None, max_degree: int | None = None,
             backend: str | object | None = None, form: GramForm | str | None = None,
             tolerances: Tolerances | None = None, budget: Budget | None = None, refine: bool = True,
             gens: Sequence[str] | None = None, radius: float | None = None) -> MinimizeResult:
    """Certified lower bound and minimisers of ``f`` on ``{eq = 0, ineq >= 0}`` (see the module docstring
    for the strategy).

    ``multiplier``: ``"auto"`` (default), ``"fixed"`` (q = (1+||v||^2)^k), ``"putinar"`` (q = 1), ``"free"``
    (q a free SOS, GEVP by bisection), or a Polynomial / positive number used as q (without ``degree``, the first
    degree is then at least deg q + deg f, rounded up to even).  ``sparsity``:
    a :class:`sospoly.Sparsity` or its spelling: ``"auto"``, ``"none"`` (= ``"dense"``), ``"correlative"``
    (``low_degree``: add the dense certificate of that degree), ``"term"``, ``"newton"``.  ``budget``: a
    :class:`sospoly.Budget` (time limit, memory; default :data:`sospoly.budget.DEFAULT_TIME_LIMIT`).  ``radius``:
    a bound on the norm of some global minimiser (a box for the proven bound of strategy step 2, beside
    the box the constraints imply and the shifted certificate, which need none).
    """
    t0 = time.perf_counter()
    tol, budget = as_tolerances(tolerances), as_budget(budget)
    if backend is not None:
        get_backend(backend, tol)        # an unknown or uninstalled solver is an error naming it, before any solve
    deadline = budget.deadline()
    if isinstance(multiplier, str) and multiplier != "auto":
        as_multiplier(multiplier)
    if isinstance(multiplier, Polynomial) and multiplier.degree > 0:
        chk = is_sos(multiplier, backend=backend, tolerances=tol)
        if not chk.is_sos:
            raise ValueError("the given multiplier q is not SOS: the certificate would not be a valid bound")
    if radius is not None:
        if isinstance(radius, (bool, np.bool_)) or not isinstance(radius, numbers.Real):
            raise TypeError(f"radius must be a positive finite number, got {type(radius).__name__} {radius!r}")
        if not (math.isfinite(radius) and radius > 0):
            raise ValueError(f"radius must be a positive finite number, got {radius!r}")
    f, eq, ineq, gens, d0 = checked_inputs(f, eq, ineq, degree, gens, budget.max_gram_side)
    if degree is None and isinstance(multiplier, Polynomial) and multiplier.degree > 0:
        d0 = max(d0, 2 * ((multiplier.degree + max(f.degree, 0) + 1) // 2))   # q (f - c) is written at deg q + deg f
    used = used_gens(gens, f, *eq, *ineq, *([multiplier] if isinstance(multiplier, Polynomial) else []))
    if 0 < len(used) < len(gens):               # a variable in no polynomial: solved without it (review 21a F5)
        res = minimize(f.with_gens(used), [g.with_gens(used) for g in eq], [h.with_gens(used) for h in ineq], degree,
                       multiplier.with_gens(used) if isinstance(multiplier, Polynomial) else multiplier,
                       sparsity=sparsity, low_degree=low_degree, max_degree=max_degree, backend=backend, form=form,
                       tolerances=tolerances, budget=budget, refine=refine, gens=used, radius=radius)
        return lifted(res, gens, used)
    if max_degree is not None and (isinstance(max_degree, (bool, np.bool_)) or not isinstance(max_degree, numbers.Real)
                                   or not math.isfinite(max_degree) or int(max_degree) != max_degree
                                   or max_degree < d0):
        raise ValueError(f"max_degree must be an integer >= the first degree {d0}, got {max_degree!r}")
    last = d0 if degree is not None else int(max_degree if max_degree is not None else d0 + 4)

    def solve(f, eq, ineq, multiplier, radius, top=last) -> MinimizeResult:
        return _strategy(f, eq, ineq, multiplier, radius, gens=gens, d0=d0, last=top, sparsity=sparsity,
                         low_degree=low_degree, form=form, backend=backend, tol=tol, budget=budget,
                         deadline=deadline, refine=refine, t0=t0)

    best = solve(f, eq, ineq, multiplier, radius)
    best = _recentred(best, f, eq, ineq, multiplier, radius, solve, tol, deadline, t0)
    return uncapped(in_callers_units(best, f, eq, ineq, tol), f, eq, ineq)


def _strategy(f, eq, ineq, multiplier, radius, *, gens, d0, last, sparsity, low_degree, form, backend, tol, budget,
              deadline, refine, t0) -> MinimizeResult:
    """Strategy steps 1-5 of the module docstring on checked data."""
    prog = scaled_program(f, eq, ineq, multiplier, radius)
    fn, eqn, ineqn, multiplier = prog.fn, prog.eqn, prog.ineqn, prog.multiplier
    unbounded = unbounded_result(fn, eqn, ineqn, gens, d0, prog.fscale, time.perf_counter() - t0)
    if unbounded is not None:                 # no bound at any degree (the SDP could miss it by its tolerance)
        return unbounded
    run = _Run(f, eq, ineq, prog=prog, gens=gens, tol=tol, budget=budget, deadline=deadline, refine=refine)
    best, cut = None, False
    for d in range(d0, last + 1, 2):
        for kind, low in _steps(deadline, sparsity, fn, eqn, ineqn, d, multiplier, d + 2 > last):
            low = low_degree if low_degree is not None else low
            for mult in _multipliers(multiplier, d, f.degree, kind == "none"):
                res = run.solve(d, mult, kind, low, form, backend)
                best = res if best is None or _better(res, best) else best
                cut = cut or res.status == SolveStatus.TIME_LIMIT
                if res.optimal or res.status == SolveStatus.TIME_LIMIT or deadline.expired:
                    break
            if (best is not None and best.optimal) or deadline.expired:
                break
        if (best is not None and best.optimal) or deadline.expired:
            break
    best = best or run._empty(SolveStatus.TIME_LIMIT, d0, multiplier, "-", "time limit reached while choosing the "
                              "certificate's sparsity")
    return _finish(best, run, time.perf_counter() - t0, cut)


def _steps(deadline, *args) -> list:
    """:func:`_choose_sparsity` under the call's deadline: no steps once it passed while they were sized (the term
    hierarchy's graph work ran past a 1 s limit for 2 s, review 38a M3)."""
    try:
        with deadline_scope(deadline):
            return _choose_sparsity(*args)
    except TimeLimitReached:
        return []


def _recentred(best: MinimizeResult, f, eq, ineq, multiplier, radius, solve, tol: Tolerances, deadline,
               t0: float) -> MinimizeResult:
    """Strategy step 8 (:func:`sospoly.recentre.recentred`): decide at the minimiser's scale, and solve the program
    translated to the best point found while the scale there keeps falling and the translation is exact."""
    from .recentre import recentred, result_in_original, translated_program

    def solve_at(t, current: MinimizeResult):
        prog = translated_program(t, f, eq, ineq, multiplier, radius)
        if prog is None:
            return None
        # a certified result is re-decided at its own degree (the translation checks its claim at the minimiser's
        # scale); an uncertified one gets the whole range of degrees
        return result_in_original(solve(*prog, top=current.degree) if current.optimal else solve(*prog), t)

    chosen = recentred(best, f, tol, solve_at, deadline, _better)
    return dataclasses.replace(chosen, seconds=time.perf_counter() - t0)


def _better(a: MinimizeResult, b: MinimizeResult) -> bool:
    if a.optimal != b.optimal:
        return a.optimal
    la, lb = a.lower_bound, b.lower_bound
    if la is None or not np.isfinite(la):
        # neither bound: feasible points (an upper bound) over none -- a later degree's points were lost behind a
        # first degree's "no certificate at this degree" (review 21a F4)
        return (lb is None or not np.isfinite(lb)) and a.upper_bound is not None and b.upper_bound is None
    return lb is None or not np.isfinite(lb) or la > lb or (
        la == lb and a.upper_bound is not None and (b.upper_bound is None or a.upper_bound < b.upper_bound))


#: statuses of an uncertified best answer that the deadline turns into TIME_LIMIT (:func:`_finish`)
_OUT_OF_TIME = frozenset({SolveStatus.OPTIMAL, SolveStatus.INACCURATE, SolveStatus.CHECK_FAILED,
                          SolveStatus.NUMERICAL_ERROR, SolveStatus.UNPROVEN, SolveStatus.NOT_SOLVED})


def _finish(best: MinimizeResult, run: _Run, seconds: float, cut: bool = False) -> MinimizeResult:
    status = best.status
    # past the deadline or a step cut short by it (review 32b L4), an uncertified answer is the time limit's, unless
    # it is a verdict (an empty set, no certificate at any degree tried) or the budget refused what was left
    if (run.deadline.expired or cut) and not best.optimal and status in _OUT_OF_TIME:
        status = SolveStatus.TIME_LIMIT
    return dataclasses.replace(best, status=status, seconds=seconds, attempts=tuple(run.attempts))


class _Run:
    """The state of one :func:`minimize` call: data, tolerances, budget, attempts so far."""

    def __init__(self, f, eq, ineq, *, prog: ScaledProgram, gens, tol, budget, deadline, refine):
        self.f, self.eq, self.ineq = f, eq, ineq
        self.fn, self.eqn, self.ineqn, self.fscale = prog.fn, prog.eqn, prog.ineqn, prog.fscale
        self.scaling, self.box, self.ball = prog.scaling, prog.box, prog.ball
        self.gens, self.tol, self.budget, self.deadline = gens, tol, budget, deadline
        self.refine = refine
        self.attempts: list[SolveAttempt] = []
        self._shift = None                      # candidates.value_shift_of of the normalised program, when needed

    def _empty(self, status, degree, mult, kind, message, n_lmivar=0) -> MinimizeResult:
        return MinimizeResult(status, None, None, (), False, n_lmivar, degree, _name_of(mult), self.gens,
                              message=message, sparsity=kind, scale=self.fscale)

    def solve(self, degree, mult, kind, low, form, backend) -> MinimizeResult:
        """One step under the deadline: the build loops check it too (:func:`sospoly.budget.deadline_scope`)."""
        try:
            with deadline_scope(self.deadline):
                return self._solve(degree, mult, kind, low, form, backend)
        except (TimeLimitReached, BudgetExceeded, MemoryError) as exc:     # the deadline, memory (no escape)
            label = "dense" if kind == "none" else kind
            status = SolveStatus.TIME_LIMIT if isinstance(exc, TimeLimitReached) else SolveStatus.BUDGET_EXCEEDED
            why = str(exc) or "out of memory (MemoryError)"
            self.attempts.append(SolveAttempt(degree, _name_of(mult), label, "-", "-", status.value, None, 0.0, why))
            return self._empty(status, degree, mult, label, why)

    def _solve(self, degree, mult, kind, low, form, backend) -> MinimizeResult:
        res = self._solve_shape(degree, mult, kind, low, form, backend, None)
        small = res.solution is not None and \
            max((G.shape[0] for G in res.solution.grams.values()), default=0) <= REDUCED_RETRY_MAX_SIDE
        if res.status == SolveStatus.UNPROVEN and small and not self.deadline.expired:
            # the solver's iterate sits near a face the identities force (rows of zeros); solved again on the
            # exactly reduced basis (sospoly.certificates.reduction), its certificate can often be proven
            again = self._solve_shape(degree, mult, kind, low, form, backend, "reduced")
            if again is not None and _better(again, res):
                return again
        return res

    def _solve_shape(self, degree, mult, kind, low, form, backend, reduce) -> MinimizeResult | None:
        label = "dense" if kind == "none" else kind
        try:
            shape = _shape_with_q(kind, self.fn, self.eqn, self.ineqn, degree, mult, self.budget.max_gram_side)
            if reduce:
                base = build_psatz(self.fn, self.eqn, self.ineqn, degree, mult, self.gens, sparsity=shape,
                                   low_degree=low if kind == "correlative" else None, budget=self.budget).shape
                if base.facial_reduction:
                    return None
                shape = base.reduced()
            psatz = build_psatz(self.fn, self.eqn, self.ineqn, degree, mult, self.gens, sparsity=shape,
                                low_degree=low if kind == "correlative" else None, budget=self.budget)
        except BudgetExceeded as exc:
            self.attempts.append(SolveAttempt(degree, _name_of(mult), label, "-", "-", "budget_exceeded", None, 0.0,
                                              str(exc)))
            return self._empty(SolveStatus.BUDGET_EXCEEDED, degree, mult, label, str(exc))
        fixed_sol = c_hi = lb = None
        found = []
        n_before = len(self.attempts)
        for fm, be in _retry_chain(form, backend, len(psatz.shape.u_bases)):
            t1 = time.perf_counter()
            if psatz.multiplier == Multiplier.FREE and fixed_sol is None:
                fixed = build_psatz(self.fn, self.eqn, self.ineqn, degree, Multiplier.FIXED, self.gens)
                lb_fixed = solve_psatz(fixed, backend=be, form=fm, tolerances=self.tol, deadline=self.deadline,
                                       prove=False)
                fixed_sol = lb_fixed.solution
                if lb_fixed.status == SolveStatus.OPTIMAL:
                    found = self._points(fixed, fixed_sol)
                    c_hi = found[0][0] if found else None
            lb = solve_psatz(psatz, backend=be, form=fm, tolerances=self.tol, c_hi=c_hi, fixed_hint=fixed_sol,
                             deadline=self.deadline, prove=False)          # (step 2 proves the bound)
            self.attempts.append(SolveAttempt(degree, _name_of(mult), label, fm.value, str(be), lb.status.value,
                                              None if lb.lower_bound is None else lb.lower_bound * self.fscale,
                                              time.perf_counter() - t1, lb.message))
            if lb.status not in _NUMERICAL or self.deadline.expired:
                break
        spent = sum(a.seconds for a in self.attempts[n_before:])
        if lb.status in _NUMERICAL and psatz.multiplier != Multiplier.FREE and not self.deadline.expired and \
                spent <= ITERATE_MAX_SECONDS:
            lb = self._iterate(psatz, form, backend) or lb
        return self._evaluate(psatz, lb, found, degree, mult, label)

    def _iterate(self, psatz, form, backend) -> LowerBound | None:
        """An "almost solved" iterate that passes the a-posteriori checks (``accept_inaccurate``), as a
        LowerBound with status INACCURATE and the iterate's level: used only through the proven bound."""
        fm, be = _retry_chain(form, backend, len(psatz.shape.u_bases))[0]
        tol = dataclasses.replace(self.tol, accept_inaccurate=True)
        lb = solve_psatz(psatz, backend=be, form=fm, tolerances=tol, deadline=self.deadline, prove=False)
        sol = lb.solution
        if lb.status != SolveStatus.INACCURATE or sol is None or sol.objective is None or not sol.grams:
            return None
        return LowerBound(SolveStatus.INACCURATE, float(sol.objective), sol, None, "inaccurate iterate")

    def _points(self, psatz, sol):
        return feasible_points(self.fn, self.eqn, self.ineqn, candidates_of(psatz, sol, self.tol), self.tol,
                                self.refine, self.deadline)

    def _evaluate(self, psatz: PsatzProblem, lb: LowerBound, found, degree, mult, label) -> MinimizeResult:
        tol, fs = self.tol, self.fscale
        bracket = None if lb.bracket is None else tuple(None if b is None else b * fs for b in lb.bracket)
        solved = (SolveStatus.OPTIMAL, SolveStatus.TIME_LIMIT, SolveStatus.INACCURATE)
        if lb.status not in solved or lb.lower_bound is None or lb.solution is None:
            status, lower, msg = unsolved_claim(psatz, lb)
            return MinimizeResult(status, None if lower is None else lower * fs, None, (), False, psatz.n_lmivar,
                                  degree, _name_of(mult), self.gens, bracket, lb.solution, 0.0, msg, sparsity=label,
                                  scale=fs)
        c_relax = float(lb.lower_bound)
        found = dedupe_points(sorted(found + self._points(psatz, lb.solution), key=lambda t: t[0]))
        pts = [(float(self.f.evaluate(self.scaling.to_original(p))) / fs, p) for _, p in found]
        found = sorted([(v, p) for v, p in pts if np.isfinite(v)], key=lambda t: t[0])
        bounds = self._trusted(found)
        upper = bounds[0][0] if bounds else None
        c, note = self._proven(psatz, lb.solution, c_relax, upper)
        msg = "; ".join(m for m in (lb.message, note) if m)
        status, optimal = lb.status, False
        if not np.isfinite(c):
            status = SolveStatus.TIME_LIMIT if self.deadline.expired else SolveStatus.UNPROVEN
            msg = f"the relaxation's value {c_relax * fs:.10g} is not proven a lower bound ({note})"
            c = None
        elif upper is not None:
            if tol.contradicts(c, upper):
                status = SolveStatus.INCONSISTENT
                msg = f"lower bound {c * fs:.10g} exceeds f at a feasible point {upper * fs:.10g}: numerical failure"
            else:
                optimal = bool(tol.certified(c, upper)) and status in (SolveStatus.OPTIMAL, SolveStatus.INACCURATE)
                status = SolveStatus.OPTIMAL if optimal else status
                c = tol.consistent(c, upper)
        near = tol.gap_tolerance(upper) if upper is not None else 0.0
        back = self.scaling.to_original
        minimizers = tuple(back(p) for val, p in bounds if val <= upper + near) if upper is not None else ()
        if len(bounds) < len(found):
            msg = "; ".join(m for m in (msg, f"{len(found) - len(bounds)} candidate(s) meet the constraints only by "
                                             "their values (not upper bounds: sospoly.analysis.candidates."
                                             "value_shift)") if m)
        return MinimizeResult(status, None if c is None else c * fs, None if upper is None else upper * fs, minimizers,
                              optimal, psatz.n_lmivar, degree, _name_of(mult), self.gens, bracket, lb.solution, 0.0,
                              msg, tuple(back(p) for _, p in bounds), label, scale=fs,
                              moment_matrices=moment_matrices_of(psatz.u, lb.solution, self.scaling.k))

    def _trusted(self, found: list) -> list:
        """The (value, point) pairs of ``found`` (normalised, ascending) whose value is an upper bound: moving the
        point onto the constraints shifts f by at most the gap tolerance (:func:`~sospoly.analysis.candidates.
        value_shift`; a point feasible by the constraints' values only may lie below the minimum, review 21a F3)."""
        if not (self.eqn or self.ineqn):
            return found
        if self._shift is None:                 # (the constraints compiled once per call)
            self._shift = value_shift_of(self.fn, self.eqn, self.ineqn)
        return [(v, p) for v, p in found if self._shift(p) <= self.tol.gap_tolerance(v)]

    def _proven(self, psatz: PsatzProblem, sol: ProgramSolution, c: float, upper) -> tuple[float, str]:
        """(the largest proven lower bound of the normalised program from the certificate at level c, or -inf;
        how it was proven or why not) -- strategy step 2; ``upper`` f at a feasible point (normalised), for
        the sublevel box."""
        from .analysis.proof import WEAK_MARGINS, global_psatz_bound, sublevel_box
        from .analysis.rigor import rigorous_psatz_bound

        best, notes = -np.inf, []
        box = self.box
        # the sublevel box needs a truly feasible point: unconstrained programs only (a candidate within the
        # feasibility tolerance of the constraints may lie below the constrained minimum)
        sub = sublevel_box(self.fn, upper) if upper is not None and not (self.eqn or self.ineqn) else None
        if sub is not None:
            box = sub if box is None else np.minimum(box, sub)
        if box is not None:
            rb = rigorous_psatz_bound(psatz, sol, c, box, ball=self.ball)
            if np.isfinite(rb.lower_bound):
                best = rb.lower_bound
                notes.append(f"proven on the box holding a minimiser (margin {rb.margin * self.fscale:.3g})")
        gb = global_psatz_bound(psatz, sol, c, deadline=self.deadline)
        if not np.isfinite(best) and not np.isfinite(gb.lower_bound) and gb.q_min > 0:
            gb = global_psatz_bound(psatz, sol, c, margins=WEAK_MARGINS, deadline=self.deadline)
        if gb.lower_bound > best:
            best = gb.lower_bound
            notes = [f"proven for every point by the shifted certificate (margin {gb.margin * self.fscale:.3g})"]
        elif not notes:
            notes.append(gb.message if self.box is None else gb.message + "; the box bound is not finite")
        if not np.isfinite(best) and gb.q_min > 0:
            best, notes = self._proven_on_face(psatz, sol, c, best, notes)
        return best, "; ".join(notes)

    def _proven_on_face(self, psatz, sol, c: float, best: float, notes: list) -> tuple[float, list]:
        """Step 2 once more when neither proof holds: every Gram matrix may lie on a singular face of the PSD
        cone (Rosenbrock's), which no shift or projection leaves; the exact proof on that face
        (:mod:`sospoly.analysis.exact_face`, small programs only) at the margins of the shifted certificate."""
        from .analysis.exact_face import face_exact_check
        from .analysis.proof import GLOBAL_MARGINS, WEAK_MARGINS

        fc = face_exact_check(psatz, sol, c, [r * max(1.0, abs(c)) for r in GLOBAL_MARGINS + WEAK_MARGINS])
        if not fc.ok:
            return best, notes + [f"exact face check: {fc.message}"]
        return fc.level, [f"proven for every point in exact arithmetic ({fc.message}; margin "
                          f"{fc.margin * self.fscale:.3g})"]
