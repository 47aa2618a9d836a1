"""User entry points: :func:`minimize` (certified polynomial optimisation) and :func:`is_sos`.

``minimize(f, eq, ineq, degree, multiplier)`` returns a :class:`MinimizeResult`:

* ``lower_bound`` -- c* of the Positivstellensatz program (a valid lower bound of
  min f on {g = 0, h >= 0}), only when the solve is OPTIMAL and checked;
* ``candidates`` -- every extracted point (kernel of the optimal Gram matrix, and
  moment matrix with a rank test), optionally polished locally, kept when feasible
  to ``Tolerances.feasibility``, sorted by f, near-duplicates merged;
* ``minimizers`` -- the candidates whose f is within the optimality tolerance of
  ``upper_bound`` (the global minimisers found, when ``optimal``);
* ``upper_bound`` -- f at the best feasible candidate;
* ``optimal`` -- ``upper_bound - lower_bound <= gap_abs + gap_rel*max(1,|upper|)``
  (:class:`~sospoly.tolerances.Tolerances`): a certificate of global optimality
  of ``minimizers[0]`` within that tolerance.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .lowering.conic import GramForm
from .analysis.extraction import Candidate, extract_from_gram, extract_from_moment
from .solvers.gevp import CompiledGevp, GevpResult, bisect
from .algebra.polynomial import Polynomial
from .certificates.program import SOSProgram
from .certificates.psatz import Multiplier, PsatzProblem, build_psatz
from .solvers.solve import ProgramSolution, solve_program
from .status import SolveStatus
from .tolerances import DEFAULT_TOLERANCES, Tolerances

__all__ = ["MinimizeResult", "SOSResult", "LowerBound", "minimize", "solve_psatz", "is_sos", "feasibility_violation",
           "candidates_of"]


@dataclass(frozen=True)
class MinimizeResult:
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

    @property
    def gap(self) -> float | None:
        if self.lower_bound is None or self.upper_bound is None:
            return None
        return self.upper_bound - self.lower_bound

    def __str__(self) -> str:
        return (f"MinimizeResult(status={self.status.value}, lower={self.lower_bound}, upper={self.upper_bound}, "
                f"optimal={self.optimal}, degree={self.degree}, n_lmivar={self.n_lmivar})")


def feasibility_violation(point: np.ndarray, eq, ineq) -> float:
    """max over constraints of |g_k| and max(0, -h_k), each relative to max(1, ||coef||_inf)."""
    worst = 0.0
    for g in eq:
        worst = max(worst, abs(g.evaluate(point)) / max(1.0, g.max_abs_coefficient()))
    for h in ineq:
        worst = max(worst, max(0.0, -h.evaluate(point)) / max(1.0, h.max_abs_coefficient()))
    return worst


def _polish(f: Polynomial, eq, ineq, x0: np.ndarray) -> np.ndarray | None:
    """Local SLSQP polish of a candidate (any feasible point gives a valid upper bound)."""
    from scipy.optimize import minimize as sp_min

    grads_f = f.gradient()
    cons = [{"type": "eq", "fun": g.evaluate, "jac": (lambda gg: (lambda v: np.array([d.evaluate(v) for d in gg])))(g.gradient())}
            for g in eq]
    cons += [{"type": "ineq", "fun": h.evaluate, "jac": (lambda hh: (lambda v: np.array([d.evaluate(v) for d in hh])))(h.gradient())}
             for h in ineq]
    try:
        res = sp_min(f.evaluate, x0, jac=lambda v: np.array([d.evaluate(v) for d in grads_f]),
                     constraints=cons, method="SLSQP", options={"ftol": 1e-14, "maxiter": 200})
    except Exception:  # a failed polish just keeps the unpolished candidate
        return None
    return np.asarray(res.x, float) if np.all(np.isfinite(res.x)) else None


def candidates_of(psatz: PsatzProblem, sol: ProgramSolution, tol: Tolerances) -> list[Candidate]:
    """Minimiser candidates from the u-certificate's Gram kernel and moment matrix."""
    basis = psatz.u.gram.b
    cands = []
    if "u" in sol.grams:
        cands += extract_from_gram(sol.grams["u"], basis, tol)
    if "u" in sol.moments:
        cands += extract_from_moment(sol.moments["u"], basis, tol)
    return cands


def _upper_from_candidates(psatz: PsatzProblem, cands, tol: Tolerances, refine: bool):
    pts = []
    for cand in cands:
        p = np.asarray(cand.point, float)
        if not np.all(np.isfinite(p)):
            continue
        if refine:
            q = _polish(psatz.f, psatz.eq, psatz.ineq, p)
            if q is not None and feasibility_violation(q, psatz.eq, psatz.ineq) <= tol.feasibility:
                # the polished point replaces the raw one: a raw candidate that violates a constraint
                # by less than the tolerance may still have f below the true minimum (no upper bound)
                pts.append(q)
                continue
        pts.append(p)
    feas = []
    for p in pts:
        if feasibility_violation(p, psatz.eq, psatz.ineq) <= tol.feasibility:
            feas.append((float(psatz.f.evaluate(p)), p))
    return _dedupe(sorted(feas, key=lambda t: t[0]))


def _dedupe(found, rtol: float = 1e-4):
    """Merge candidates closer than rtol*max(1,|p|) (extraction noise), keeping the lowest f."""
    uniq = []
    for val, p in found:
        if all(np.linalg.norm(p - q) > rtol * max(1.0, np.linalg.norm(q)) for _, q in uniq):
            uniq.append((val, p))
    return uniq


@dataclass(frozen=True)
class LowerBound:
    """Outcome of one Positivstellensatz solve: the certified c*, its certificate, and for
    the free multiplier the final bisection bracket."""
    status: SolveStatus
    lower_bound: float | None
    solution: ProgramSolution | None
    bracket: tuple | None = None
    message: str = ""


def solve_psatz(psatz: PsatzProblem, *, backend=None, form: GramForm = GramForm.IMAGE,
                tolerances: Tolerances = DEFAULT_TOLERANCES, c_hi: float | None = None,
                fixed_hint: ProgramSolution | None = None) -> LowerBound:
    """Solve a Positivstellensatz program: one SDP (fixed q) or the GEVP bisection (free q).

    For the free multiplier the bracket starts from the fixed-q SDP's c* (solved here
    unless ``fixed_hint`` gives it) and from ``c_hi`` (f at a feasible point), if known.
    ``psatz`` may also be a :class:`sospoly.lowering.compiled.CompiledInstance` (a compiled structure
    filled with one instance's numbers): then only its conic data is solved.
    """
    from .lowering.compiled import CompiledInstance

    if isinstance(psatz, CompiledInstance):
        return psatz.compiled.solve_theta(psatz.theta, backend=backend, tolerances=tolerances, problem=psatz.problem)
    if not psatz.eq and not psatz.ineq and psatz.f.degree % 2:
        # f of odd degree on all of R^n is unbounded below, so no certificate exists at any degree.
        # The SDP is then only *weakly* infeasible (no Farkas certificate): solvers cannot detect it
        # and report numerical errors, so decide it exactly here.
        return LowerBound(SolveStatus.INFEASIBLE, None, None, None,
                          f"f has odd degree {psatz.f.degree} and there are no constraints: f is unbounded below")
    if psatz.multiplier == Multiplier.FREE:
        c_lo = None
        if fixed_hint is None:
            fixed = build_psatz(psatz.f, psatz.eq, psatz.ineq, psatz.degree, Multiplier.FIXED, gens=psatz.gens)
            fixed_hint = solve_program(fixed.program, backend, form, tolerances)
        if fixed_hint.status == SolveStatus.OPTIMAL:
            c_lo = fixed_hint.objective
        g: GevpResult = bisect(CompiledGevp(psatz, backend, form, tolerances), c_lo, c_hi)
        return LowerBound(g.status, g.lower_bound, g.solution, g.bracket, g.message)
    return lower_bound_of(solve_program(psatz.program, backend, form, tolerances), psatz.degree)


def lower_bound_of(sol: ProgramSolution, degree: int) -> LowerBound:
    """The LowerBound of a fixed-multiplier solve (c* when OPTIMAL, a status message otherwise)."""
    if sol.status == SolveStatus.OPTIMAL:
        return LowerBound(sol.status, sol.objective, sol)
    lb = np.inf if sol.status == SolveStatus.UNBOUNDED else None
    msg = {SolveStatus.INFEASIBLE: f"no Positivstellensatz certificate at degree {degree}; try a larger degree",
           SolveStatus.UNBOUNDED: "c is unbounded: the constraint set is empty"}.get(sol.status, sol.message)
    return LowerBound(sol.status, lb, sol, None, msg)


def minimize(f, eq=(), ineq=(), degree: int | None = None, multiplier=Multiplier.FIXED, *,
             backend=None, form: GramForm = GramForm.IMAGE, tolerances: Tolerances = DEFAULT_TOLERANCES,
             refine: bool = True, gens=None) -> MinimizeResult:
    """Certified lower bound and minimisers of ``f`` on ``{eq = 0, ineq >= 0}`` (see module docstring).

    ``multiplier``: ``"fixed"`` (q = (1+||v||^2)^k, one SDP), ``"free"`` (q free SOS,
    GEVP by bisection), or a Polynomial / positive number used as q.
    """
    t0 = time.perf_counter()
    if isinstance(multiplier, Polynomial) and multiplier.degree > 0:
        chk = is_sos(multiplier, backend=backend, tolerances=tolerances)
        if not chk.is_sos:
            raise ValueError("the given multiplier q is not SOS: the certificate would not be a valid bound")
    psatz = build_psatz(f, eq, ineq, degree, multiplier, gens=gens)
    mult_name = "given" if isinstance(multiplier, (Polynomial, int, float)) else psatz.multiplier.value
    found = []
    c_hi = fixed_sol = None
    if psatz.multiplier == Multiplier.FREE:
        # candidates of the fixed-q SDP give the bisection its upper end
        fixed = build_psatz(psatz.f, psatz.eq, psatz.ineq, psatz.degree, Multiplier.FIXED, gens=psatz.gens)
        fixed_sol = solve_program(fixed.program, backend, form, tolerances)
        if fixed_sol.status == SolveStatus.OPTIMAL:
            found = _upper_from_candidates(fixed, candidates_of(fixed, fixed_sol, tolerances), tolerances, refine)
            c_hi = found[0][0] if found else None
    lb = solve_psatz(psatz, backend=backend, form=form, tolerances=tolerances, c_hi=c_hi, fixed_hint=fixed_sol)
    elapsed = time.perf_counter() - t0
    if lb.status != SolveStatus.OPTIMAL:
        return MinimizeResult(lb.status, lb.lower_bound, None, (), False, psatz.n_lmivar, psatz.degree, mult_name,
                              psatz.gens, lb.bracket, lb.solution, elapsed, lb.message)
    found = found + _upper_from_candidates(psatz, candidates_of(psatz, lb.solution, tolerances), tolerances, refine)
    found = _dedupe(sorted(found, key=lambda t: t[0]))
    upper = found[0][0] if found else None
    status, optimal, msg = SolveStatus.OPTIMAL, tolerances.certified(lb.lower_bound, upper), ""
    if upper is not None and lb.lower_bound - upper > tolerances.gap_abs + tolerances.gap_rel * max(1.0, abs(upper)):
        status, optimal = SolveStatus.INCONSISTENT, False
        msg = f"lower bound {lb.lower_bound:.10g} exceeds f at a feasible point {upper:.10g}: numerical failure"
    near = tolerances.gap_abs + tolerances.gap_rel * max(1.0, abs(upper)) if upper is not None else 0.0
    minimizers = tuple(p for val, p in found if val <= upper + near) if upper is not None else ()
    return MinimizeResult(status, lb.lower_bound, upper, minimizers, optimal, psatz.n_lmivar,
                          psatz.degree, mult_name, psatz.gens, lb.bracket, lb.solution,
                          time.perf_counter() - t0, msg, tuple(p for _, p in found))


@dataclass(frozen=True)
class SOSResult:
    """``is_sos`` answer; when True, ``p = sum_k decomposition[k]**2`` up to the solver's accuracy."""
    is_sos: bool
    status: SolveStatus
    gram: np.ndarray | None
    basis: np.ndarray | None
    decomposition: tuple = ()
    min_eigenvalue: float | None = None
    message: str = ""


def is_sos(p, *, backend=None, form: GramForm = GramForm.IMAGE,
           tolerances: Tolerances = DEFAULT_TOLERANCES) -> SOSResult:
    """Decide whether ``p`` is a sum of squares (Gram matrix method, SPEC §4)."""
    if not isinstance(p, Polynomial):
        raise TypeError(f"is_sos needs a sospoly Polynomial, got {type(p).__name__}")
    if p.is_zero:
        return SOSResult(True, SolveStatus.FEASIBLE, np.zeros((1, 1)), np.zeros((1, max(p.nvars, 1)), int), (), 0.0)
    if p.degree % 2:
        return SOSResult(False, SolveStatus.INFEASIBLE, None, None, message=f"odd degree {p.degree}")
    if p.nvars == 0 or p.degree == 0:
        c = p.coefficient((0,) * p.nvars)
        return SOSResult(c >= 0, SolveStatus.FEASIBLE if c >= 0 else SolveStatus.INFEASIBLE,
                         np.array([[c]]), np.zeros((1, p.nvars), int),
                         (Polynomial.constant(np.sqrt(max(c, 0.0)), p.gens),) if c >= 0 else ())
    prog = SOSProgram(p.gens)
    con = prog.add_sos(p, degree=p.degree, name="p")
    sol = solve_program(prog, backend, form, tolerances)
    if not sol.status.ok:
        return SOSResult(False, sol.status, None, con.gram.b, message=sol.message)
    G = sol.grams["p"]
    lam, V = np.linalg.eigh(G)
    decomposition = []
    for k in range(lam.size):
        if lam[k] > tolerances.psd_margin * max(1.0, lam[-1]):
            coef = np.sqrt(lam[k]) * V[:, k]
            decomposition.append(Polynomial(p.gens, {tuple(int(t) for t in e): float(c)
                                                     for e, c in zip(con.gram.b, coef) if c != 0.0}))
    return SOSResult(True, sol.status, G, con.gram.b, tuple(decomposition), float(lam[0]))
