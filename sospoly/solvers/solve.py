"""Solve an SOS program and check its certificate a posteriori.

A bound or certificate is only reported when the solver said *solved* **and**
the returned numbers check out independently of the solver's word
(:class:`~sospoly.tolerances.Tolerances` documents the margins):

* every Gram matrix, recomputed from the primal x (so that the polynomial
  identity u(v) = b(v)^T G b(v) holds exactly in the image form), has
  ``lambda_min >= -psd_margin * max(floor, max|G|)``;
* the linear equalities (zero-cone rows) hold to ``identity_residual`` relative to
  ``max(floor, max|b|)`` of their rows;
* the coefficient identity between each SOS expression and its Gram matrix holds
  to ``identity_residual`` (non-trivial for the kernel form and cvxpy).

``floor`` is 1, or the program's own scale max|b| where that is smaller: with a floor of 1 the
margins are absolute, and a program whose coefficients are all ~1e-10 passed with a level 100%
above its minimum (review 21a F2).  Such a program is also solved in exact scaled form
(:func:`solve_conic`: its right-hand side b times a power of two, x divided by it after), as the
solvers' own stopping rules have absolute parts that a tiny program sits below.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..budget import Deadline
from ..scaling import MAX_POW2_EXP
from .balance import balanced_psd, balancing, block_scalings
from .backends import ConicSolution, RawStatus, cut_by_deadline, get_backend
from .optimality import check_optimality
from .rays import check_infeasibility, check_primal_point, check_unbounded_ray
from ..lowering.conic import ConicProblem, GramForm, lower
from ..algebra.polynomial import Polynomial
from ..certificates.program import Sense, SOSProgram
from ..status import SolveStatus
from ..tolerances import DEFAULT_TOLERANCES, Tolerances, as_tolerances

__all__ = ["ProgramSolution", "LowerBound", "lower_bound_of", "solve_program", "solve_conic", "check_certificate",
           "check_floor", "ConicResult", "solve_conic_problem", "RESCALE_BELOW"]


@dataclass(frozen=True)
class ProgramSolution:
    """Result of solving an :class:`SOSProgram`.

    ``grams`` maps every SOS constraint and SOS multiplier block name to its Gram
    matrix; ``moments`` maps the same names to the dual (moment) matrices.
    """

    status: SolveStatus
    objective: float | None
    x: np.ndarray | None
    grams: dict = field(default_factory=dict)
    moments: dict = field(default_factory=dict)
    min_eigenvalues: dict = field(default_factory=dict)
    residual: float | None = None
    attempts: tuple = ()
    n_lmivar: int = 0
    seconds: float = 0.0
    message: str = ""

    @property
    def stopped_for_time(self) -> bool:
        """Did the caller's deadline cut the solver's retry chain short (:func:`~.backends.cut_by_deadline`)?"""
        return cut_by_deadline(self.attempts)

    def value(self, expr) -> Polynomial | float:
        """Numeric value of a decision expression (LinPoly) at the solution."""
        if self.x is None:
            raise ValueError(f"no solution values (status {self.status.value})")
        return expr.value(self.x)

    def block_values(self, program: SOSProgram, name: str) -> np.ndarray:
        blk = program.block(name)
        return self.x[blk.slice]


def check_certificate(problem: ConicProblem, x: np.ndarray, tol: Tolerances) -> tuple[bool, dict, float, str]:
    """A-posteriori check of a primal point; returns (ok, min eigenvalues, residual, message)."""
    if x is None or not np.all(np.isfinite(x)):
        return False, {}, np.inf, "non-finite solution"
    grams = problem.gram_matrices(x)
    mins = {}
    ok = True
    msg = []
    floor = check_floor(problem)
    floors = _block_floors(problem, floor)
    for name, G in grams.items():
        scale = float(np.max(np.abs(G))) if G.size else 0.0
        lam = float(np.linalg.eigvalsh(G)[0]) if G.size else 0.0
        mins[name] = lam
        if not tol.psd_accepts(lam, scale, floors[name]):
            ok = False
            msg.append(f"Gram {name}: lambda_min {lam:.3g} below the PSD margin "
                       f"({tol.psd_margin:g} * max({floors[name]:.3g}, {scale:.3g}))")
    for label, lam, scale in _scalar_cone_margins(problem, x):
        mins[label] = lam
        if not tol.psd_accepts(lam, scale, floor):
            ok = False
            msg.append(f"{label}: violated by {-lam:.3g} (margin {tol.psd_margin:g} * max({floor:.3g}, {scale:.3g}))")
    scalings = block_scalings(problem)
    if any(S is not None for S in scalings.values()):
        good, why = balanced_psd(problem, scalings, grams, tol)      # the monomials' own scale (review 39b)
        if not good:
            ok = False
            msg.append(why)
    # zero-cone rows
    resid = 0.0
    row = 0
    for cone in problem.cones:
        if cone.kind == "zero":
            r = problem.b[row:row + cone.dim] - problem.A[row:row + cone.dim] @ x
            bscale = max(floor, float(np.max(np.abs(problem.b[row:row + cone.dim]))) if cone.dim else 1.0)
            resid = max(resid, float(np.max(np.abs(r))) / bscale if cone.dim else 0.0)
        row += cone.dim
    if resid > tol.identity_residual:
        ok = False
        msg.append(f"equality residual {resid:.3g} > {tol.identity_residual:g}")
    return ok, mins, resid, "; ".join(msg)


def _block_floors(problem: ConicProblem, floor: float) -> dict:
    """Each PSD block's own floor (review 26a F8): min(``floor``, max|b| over the block's rows) where the block's
    rows carry data of their own (an image-form SOS constraint: its polynomial's coefficients, an LMI: its constant
    entries), ``floor`` where they carry none (b = 0 there: an SOS multiplier, a PSD matrix variable, whose scale is
    that of the rows they enter).  With the program-wide floor, a block of data
    ~1e-10 beside an O(1) block was measured against an absolute margin 1e-7 and passed indefinite by 56% of its
    own entries.  A kernel-form SOS constraint's data are the coefficient-matching rows its Gram variables enter."""
    out = {}
    n_zero = sum(c.dim for c in problem.cones if c.kind == "zero")
    A = problem.A.tocsc()
    for blk in problem.psd_blocks:
        n = blk.size * (blk.size + 1) // 2
        if blk.var_start is not None and blk.source == "constraint":     # kernel form: its coefficient matching
            rows = A.indices[A.indptr[blk.var_start]:A.indptr[blk.var_start + n]]
            rows = problem.b[rows[rows < n_zero]]
        else:
            rows = problem.b[blk.row_start:blk.row_start + n]
        bmax = float(np.max(np.abs(rows))) if rows.size else 0.0
        out[blk.name] = min(floor, bmax) if 0.0 < bmax and np.isfinite(bmax) else floor
    return out


def check_floor(problem: ConicProblem) -> float:
    """The floor of :func:`check_certificate`'s margins (module docstring): min(1, max|b|), 1 where b is 0."""
    bmax = float(np.max(np.abs(problem.b))) if problem.b.size else 0.0
    return min(1.0, bmax) if bmax > 0 and np.isfinite(bmax) else 1.0


#: :func:`solve_conic` solves a program whose right-hand side has max|b| below this in exact scaled form (b times
#: a power of two bringing max|b| into [1, 2)); above it (tritools' normalised programs: max|b| >= 1) as it is
RESCALE_BELOW = 2.0 ** -10


def _rhs_scale(problem: ConicProblem) -> float:
    """The power of two alpha with alpha max|b| in [1, 2) where max|b| < :data:`RESCALE_BELOW` (1 otherwise, or for
    a parametric problem): A x + s = b, s in K holds iff A (alpha x) + alpha s = alpha b with alpha s in K, so the
    scaled program's solution divided by alpha is the program's, exactly."""
    if problem.params or not problem.b.size:
        return 1.0
    bmax = float(np.max(np.abs(problem.b)))
    if not (0.0 < bmax < RESCALE_BELOW and np.isfinite(bmax)):
        return 1.0
    return math.ldexp(1.0, min(-math.frexp(bmax)[1] + 1, MAX_POW2_EXP))     # (a subnormal bmax: 2^1074 overflowed)


def _unscaled(sol: ConicSolution, alpha: float) -> ConicSolution:
    """The solution of the program from that of its scaled form (:func:`_rhs_scale`): x and the objectives over
    alpha, the dual z unchanged (a cone's dual is invariant under the scaling of b)."""
    if alpha == 1.0:
        return sol
    div = (lambda v: None if v is None else v / alpha)         # noqa: E731
    return ConicSolution(sol.raw_status, div(sol.x), sol.z, div(sol.primal_objective), div(sol.dual_objective),
                         sol.attempts)


def _scalar_cone_margins(problem: ConicProblem, x: np.ndarray) -> list:
    """(label, margin, scale) of every nonnegative block (min slack) and second-order cone (t - ||y||),
    recomputed from x: checked with the PSD rule of :meth:`~sospoly.Tolerances.psd_accepts`."""
    out, row = [], 0
    s = None
    for k, cone in enumerate(problem.cones):
        if cone.kind in ("nonneg", "soc") and cone.dim:
            s = problem.slack(x) if s is None else s
            v = s[row:row + cone.dim]
            if cone.kind == "nonneg":
                out.append((f"nonneg cone {k}", float(v.min()), float(np.abs(v).max())))
            else:
                norm = float(np.linalg.norm(v[1:]))
                out.append((f"second-order cone {k}", float(v[0]) - norm, max(abs(float(v[0])), norm)))
        row += cone.dim
    return out


def solve_conic(problem: ConicProblem, backend=None, tolerances: Tolerances = DEFAULT_TOLERANCES,
                feasibility: bool = False, extra_check=None, retry: bool = True,
                deadline: Deadline | None = None) -> tuple[SolveStatus, ConicSolution, dict, float, str]:
    """Solve and classify; returns (status, raw solution, min eigenvalues, residual, message).

    ``extra_check(x, min_eigenvalues) -> (ok, message)`` adds a caller-specific
    acceptance rule on top of :func:`check_certificate`.  ``deadline``
    (:class:`~sospoly.budget.Deadline`) bounds the solve's wall time: a solve that runs out of
    time returns ``TIME_LIMIT``.
    """
    tolerances = as_tolerances(tolerances)
    be = get_backend(backend, tolerances)
    if deadline is not None and deadline.expired:
        return SolveStatus.TIME_LIMIT, ConicSolution(RawStatus.TIME_LIMIT, None, None, None, None, ()), {}, np.nan, \
            "time limit reached before the solve"
    cache = {}
    bal = balancing(problem)                    # the monomials' balanced scale (review 39b; None: already there)
    base = problem if bal is None else bal.problem(problem)
    alpha = _rhs_scale(base)
    work = base if alpha == 1.0 else replace(base, b=base.b * alpha)

    def checked(x):
        """The a-posteriori check of ``x`` (with ``extra_check``), made once per iterate."""
        if "last" in cache and cache["last"][0] is x:
            return cache["last"][1]
        res = check_certificate(problem, x, tolerances)
        if res[0] and extra_check is not None:
            ok, msg = extra_check(x, res[1])
            if not ok:
                res = (False, res[1], res[2], msg)
        cache["last"] = (x, res)
        return res

    def accept(x, z):           # (an iterate of the scaled form: checked as the program's)
        if (alpha == 1.0 and bal is None) or x is None:
            return checked(x)[0]
        if "scaled" not in cache or cache["scaled"][0] is not x:
            cache["scaled"] = (x, x / alpha if bal is None else bal.x(x / alpha))
        return checked(cache["scaled"][1])[0]

    sol = be.solve(work, accept=accept, retry=retry, deadline=deadline)
    if alpha != 1.0 or bal is not None:
        scaled_x = sol.x
        sol = _unscaled(sol, alpha)
        if bal is not None:
            sol = replace(sol, x=bal.x(sol.x), z=bal.z(sol.z))
        if "scaled" in cache and cache["scaled"][0] is scaled_x:
            sol = replace(sol, x=cache["scaled"][1])       # (the array checked: its cached check)
    if sol.raw_status == RawStatus.SOLVED:
        ok, mins, resid, msg = checked(sol.x)
        if ok:
            return (SolveStatus.FEASIBLE if feasibility else SolveStatus.OPTIMAL), sol, mins, resid, ""
        return SolveStatus.CHECK_FAILED, sol, mins, resid, msg
    if sol.raw_status == RawStatus.ALMOST_SOLVED and tolerances.accept_inaccurate and sol.x is not None:
        ok, mins, resid, msg = checked(sol.x)
        if ok:
            return SolveStatus.INACCURATE, sol, mins, resid, "inaccurate iterate; the a-posteriori checks passed"
        return SolveStatus.CHECK_FAILED, sol, mins, resid, msg
    status = {
        RawStatus.PRIMAL_INFEASIBLE: SolveStatus.INFEASIBLE,
        RawStatus.DUAL_INFEASIBLE: SolveStatus.UNBOUNDED,
        RawStatus.ALMOST_SOLVED: SolveStatus.INACCURATE,
        RawStatus.ALMOST_INFEASIBLE: SolveStatus.INACCURATE,
        RawStatus.TIME_LIMIT: SolveStatus.TIME_LIMIT,
    }.get(sol.raw_status, SolveStatus.NUMERICAL_ERROR)
    detail = "; ".join(f"{a.label}: {a.solver_status}" for a in sol.attempts)
    if feasibility and status == SolveStatus.UNBOUNDED:  # a feasibility problem has no objective to be unbounded
        status = SolveStatus.NUMERICAL_ERROR
    elif status == SolveStatus.UNBOUNDED:
        ok, why = check_unbounded_ray(problem, sol.x, tolerances)
        if not ok:
            status, detail = SolveStatus.NUMERICAL_ERROR, f"{detail}; its unboundedness ray fails the check: {why}"
    elif status == SolveStatus.INFEASIBLE and sol.z is not None:     # (cvxpy gives no certificate: its word)
        ok, why = check_infeasibility(problem, sol.z, tolerances)
        if not ok:
            status, detail = SolveStatus.NUMERICAL_ERROR, f"{detail}; its infeasibility certificate fails the " \
                                                          f"check: {why}"
    return status, sol, {}, np.nan, detail


@dataclass(frozen=True)
class ConicResult:
    """Outcome of :func:`solve_conic_problem`: the status (``SolveStatus``), the caller's objective at x (None
    unless x passed the primal checks: ``optimal`` when the dual z proves it optimal too,
    :func:`~sospoly.solvers.rays.check_dual_certificate`; ``inaccurate`` when it does not -- a feasible point's
    value), the primal x, the dual z, the solver attempts and a message."""
    status: object
    objective: float | None
    x: np.ndarray | None
    z: np.ndarray | None
    attempts: tuple = ()
    message: str = ""


def solve_conic_problem(problem: ConicProblem, backend=None, tolerances=None) -> ConicResult:
    """Solve a lowered (or read: SDPA, CBF) conic problem with ``backend`` (default Clarabel) and check the
    answer a posteriori (:func:`solve_conic`; ``optimal`` also needs x feasible at each cone's own scale,
    :func:`~sospoly.solvers.rays.check_primal_point`, and the primal-dual pair to prove the objective at the
    objective's own scale, :func:`~sospoly.solvers.optimality.check_optimality` -- the rule of
    :func:`solve_program` too --, else ``inaccurate``, with the objective only while the primal's cone violation
    leaves it a value of the program); a :class:`ConicResult` with the caller's objective
    ``objective_sign * q^T x + objective_offset``."""
    if problem.params:
        raise ValueError("solve: instantiate the problem's parameters first (ConicProblem.instantiate)")
    tolerances = as_tolerances(tolerances or DEFAULT_TOLERANCES)
    status, sol, _, resid, msg = solve_conic(problem, backend, tolerances)
    obj = None
    if status.ok and sol.x is not None:
        obj = problem.objective_sign * float(problem.q @ sol.x) + problem.objective_offset
        ok, why = check_primal_point(problem, sol.x, tolerances)
        if not ok:
            status, obj, msg = SolveStatus.INACCURATE, None, f"the point is not feasible at its cones' own scale: {why}"
        else:
            status, keep, msg = _optimality_verdict(problem, sol, status, tolerances, msg)
            obj = obj if keep else None
    return ConicResult(status, obj, sol.x, sol.z, sol.attempts, msg)


def _optimality_verdict(problem: ConicProblem, sol: ConicSolution, status: SolveStatus, tolerances: Tolerances,
                        msg: str) -> tuple[SolveStatus, bool, str]:
    """The one rule of ``optimal`` for :func:`solve_program` and :func:`solve_conic_problem` (review 26a F4): an
    OPTIMAL answer of :func:`solve_conic` stays OPTIMAL only when the primal-dual pair proves its objective at the
    objective's own scale (:func:`~sospoly.solvers.optimality.check_optimality`), else it is INACCURATE.  Returns
    (status, whether the objective is still a value of the program -- the primal cone violation's effect on it is
    within the tolerance --, message).  A back-end without a dual (z None) keeps its word."""
    if status != SolveStatus.OPTIMAL or sol.z is None or sol.x is None:
        return status, status.ok, msg
    bal = balancing(problem)        # (the program solve_conic solved: the same terms at the monomials' scale)
    opt = check_optimality(problem, sol.x, sol.z, tolerances) if bal is None else \
        check_optimality(bal.problem(problem), sol.x / bal.cols, sol.z / bal.rows, tolerances)
    if opt.ok:
        return status, True, msg
    if opt.primal_ok:
        return SolveStatus.INACCURATE, True, (f"a feasible point (checked) whose optimality the dual does not prove: "
                                              f"{opt.describe()}; the objective is its value")
    return SolveStatus.INACCURATE, False, f"the primal cone violation moves the objective too far: {opt.describe()}"


def solve_program(program: SOSProgram, backend=None, form: GramForm = GramForm.IMAGE,
                  tolerances: Tolerances = DEFAULT_TOLERANCES, problem: ConicProblem | None = None,
                  deadline: Deadline | None = None) -> ProgramSolution:
    """Lower (unless ``problem`` is given), solve and check ``program``: ``optimal`` when the certificate passes
    :func:`check_certificate` and the primal-dual pair proves the objective at the objective's own scale
    (:func:`~sospoly.solvers.optimality.check_optimality`, the rule of :func:`solve_conic_problem`); otherwise
    ``inaccurate``, with the objective, x and Gram matrices of the checked point when only the dual fails to prove
    it (or with ``Tolerances.accept_inaccurate``), without them when the point's cone violation moves the objective
    beyond the tolerance."""
    tolerances = as_tolerances(tolerances)
    if problem is None:
        problem = lower(program, form)
    feas = program.sense == Sense.FEASIBILITY or program.objective is None
    status, sol, mins, resid, msg = solve_conic(problem, backend, tolerances, feasibility=feas, deadline=deadline)
    n_lmivar = program.n_lmivar()
    keep = False
    if not feas:
        status, keep, msg = _optimality_verdict(problem, sol, status, tolerances, msg)
    accepted_iterate = status == SolveStatus.INACCURATE and bool(mins) and (tolerances.accept_inaccurate or keep)
    if not status.ok and not accepted_iterate:
        return ProgramSolution(status, None, sol.x, attempts=sol.attempts, n_lmivar=n_lmivar,
                               seconds=sol.seconds, message=msg, min_eigenvalues=mins)
    x = sol.x
    obj = None
    if not feas:
        obj = problem.objective_sign * float(problem.q @ x) + problem.objective_offset
    return ProgramSolution(status, obj, x[: program.n_vars].copy(), problem.gram_matrices(x),
                           problem.dual_matrices(sol.z), mins, resid, sol.attempts, n_lmivar, sol.seconds, msg)


@dataclass(frozen=True)
class LowerBound:
    """Outcome of one Positivstellensatz solve: the certified c*, its certificate, and for
    the free multiplier the final bisection bracket."""
    status: SolveStatus
    lower_bound: float | None
    solution: ProgramSolution | None
    bracket: tuple | None = None
    message: str = ""


def lower_bound_of(sol: ProgramSolution, degree: int) -> LowerBound:
    """The LowerBound of a fixed-multiplier solve (c* when OPTIMAL, a status message otherwise)."""
    if sol.status == SolveStatus.OPTIMAL:
        return LowerBound(sol.status, sol.objective, sol)
    lb = np.inf if sol.status == SolveStatus.UNBOUNDED else None
    msg = {SolveStatus.INFEASIBLE: f"no Positivstellensatz certificate at degree {degree}; try a larger degree",
           SolveStatus.UNBOUNDED: "c is unbounded: the constraint set is empty",
           SolveStatus.TIME_LIMIT: f"time limit reached at degree {degree}"}.get(sol.status, sol.message)
    return LowerBound(sol.status, lb, sol, None, msg)
