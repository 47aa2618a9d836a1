"""Solver back-ends for :class:`~sospoly.lowering.conic.ConicProblem`.

This module and :mod:`.cvxpy_backend` are the only ones of sospoly that import a solver.  The back-ends:

* :class:`ClarabelBackend` (default): Clarabel called directly on the standard
  form, with a retry chain of settings for the routine numerical failures of
  large batches (each attempt is recorded).  pyo3's ``PanicException`` (a
  BaseException) is caught, the solver object is discarded and the next attempt
  builds a fresh one.
* :class:`IpmBackend`: the small interior-point method of :mod:`sospoly.solvers.ipm` (Schur
  complement of the size of the free scalars), falling back to Clarabel when it
  does not converge or its answer fails the a-posteriori check; both attempts are
  recorded.
* :class:`CvxpyBackend` (:mod:`.cvxpy_backend`): the same conic data re-expressed as a cvxpy problem and
  solved by any installed cvxpy SDP solver (for cross-checking).
"""
from __future__ import annotations

import enum
import math
import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..budget import AUTO_IPM_MAX_BYTES as _AUTO_IPM_MAX_BYTES
from ..budget import CLARABEL_TIME_MODEL, BudgetExceeded, Deadline, estimate_size, memory_room
from ..lowering.conic import ConicProblem
from ..tolerances import DEFAULT_TOLERANCES, Tolerances, as_tolerances
from .interrupt import solve_interruptibly, stopped_for_time
from .optional import check_cvxpy_solver, cvxpy_available, import_cvxpy  # noqa: F401 - re-exported
from .retry_chain import (CLARABEL_FAST_CHAIN, CLARABEL_RETRY_CHAIN, CLARABEL_SPLIT_CHAIN, QDLDL_MAX_PSD_SIDE,
                          RETRY_MIN_ITERATIONS)
from .rays import check_infeasibility, check_unbounded_ray

__all__ = ["RawStatus", "Attempt", "ConicSolution", "ClarabelBackend", "IpmBackend", "AutoBackend",
           "CLARABEL_FAST_CHAIN", "CLARABEL_SPLIT_CHAIN", "get_backend", "cvxpy_available", "import_cvxpy"]


class RawStatus(str, enum.Enum):
    """Solver-independent summary of what the solver itself said."""
    SOLVED = "solved"
    ALMOST_SOLVED = "almost_solved"
    PRIMAL_INFEASIBLE = "primal_infeasible"
    DUAL_INFEASIBLE = "dual_infeasible"
    ALMOST_INFEASIBLE = "almost_infeasible"
    TIME_LIMIT = "time_limit"
    FAILED = "failed"


@dataclass(frozen=True)
class Attempt:
    """One solver call.  ``start_seconds``: its measured uninterruptible start (set-up plus two iterations'
    worth: the initial point and the first iteration), which bounds when a retry may still start."""
    label: str
    raw_status: RawStatus
    solver_status: str
    iterations: int
    seconds: float
    start_seconds: float = 0.0


@dataclass(frozen=True)
class ConicSolution:
    raw_status: RawStatus
    x: np.ndarray | None
    z: np.ndarray | None
    primal_objective: float | None
    dual_objective: float | None
    attempts: tuple = field(default_factory=tuple)

    @property
    def seconds(self) -> float:
        return sum(a.seconds for a in self.attempts)

    @property
    def stopped_for_time(self) -> bool:
        """:func:`cut_by_deadline` of the attempts."""
        return cut_by_deadline(self.attempts)


def cut_by_deadline(attempts) -> bool:
    """Did the caller's deadline end a retry chain short after it began (an attempt stopped at it, or not started
    for lack of time)?  Then an answer kept from an earlier attempt is not the chain's last word (review 34b: a
    robust search took such a sub-problem as exhausted).  A solve the deadline ended before any attempt has no
    attempts and its own status ``time_limit``."""
    return any(a.raw_status == RawStatus.TIME_LIMIT for a in attempts)


_CLARABEL_MAP = {
    "Solved": RawStatus.SOLVED,
    "AlmostSolved": RawStatus.ALMOST_SOLVED,
    "PrimalInfeasible": RawStatus.PRIMAL_INFEASIBLE,
    "DualInfeasible": RawStatus.DUAL_INFEASIBLE,
    "AlmostPrimalInfeasible": RawStatus.ALMOST_INFEASIBLE,
    "AlmostDualInfeasible": RawStatus.ALMOST_INFEASIBLE,
    "MaxTime": RawStatus.TIME_LIMIT,
}

#: "no deadline" for :meth:`ClarabelBackend.solve_once`'s ``stop_by`` (None there means "the ``deadline``")
_NO_DEADLINE = Deadline(None)


def _check_native_memory(problem: ConicProblem) -> None:
    """:class:`~sospoly.budget.BudgetExceeded` when Clarabel's estimated memory for ``problem`` exceeds the
    address space left under the process's limit: a failed allocation in native code aborts the
    interpreter (no MemoryError), so the call is not made."""
    room, what = memory_room(None)
    if room is None:
        return
    psd = [c.size for c in problem.cones if c.kind == "psd"]
    zero = sum(c.dim for c in problem.cones if c.kind == "zero")
    size = estimate_size(psd, problem.n_cols, zero)
    if size.clarabel_bytes > room:
        raise BudgetExceeded(f"Clarabel would need about {size.clarabel_bytes / 2 ** 20:.0f} MiB ({size.describe()}), "
                             f"more than {what} ({room / 2 ** 20:.0f} MiB)", size,
                             "raise the limit (ulimit -v) or use a lower degree or a sparse certificate")


class ClarabelBackend:
    name = "clarabel"

    def __init__(self, tolerances: Tolerances = DEFAULT_TOLERANCES, retry_chain=CLARABEL_RETRY_CHAIN, *,
                 skip=(), **settings):
        """``skip``: labels of chain attempts already made on the program (e.g. a quick first solve before the
        full chain): :meth:`_chain` skips every attempt whose effective settings repeat theirs."""
        self.tolerances = as_tolerances(tolerances)
        self.retry_chain = tuple(retry_chain)
        self.skip = frozenset(str(label).split("/")[0] for label in skip)
        self.settings = settings

    def _settings(self, overrides):
        import clarabel

        s = clarabel.DefaultSettings()
        s.verbose = False
        s.tol_gap_abs = self.tolerances.solver_gap_abs
        s.tol_gap_rel = self.tolerances.solver_gap_rel
        s.tol_feas = self.tolerances.solver_feas
        s.max_iter = self.tolerances.solver_max_iter
        s.presolve_enable = False   # keep row structure: duals map 1:1 to our rows
        for k, v in {**self.settings, **overrides}.items():
            setattr(s, k, v)
        return s

    @staticmethod
    def _cones(problem: ConicProblem):
        import clarabel

        out = []
        for c in problem.cones:
            if c.kind == "zero":
                out.append(clarabel.ZeroConeT(c.dim))
            elif c.kind == "nonneg":
                out.append(clarabel.NonnegativeConeT(c.dim))
            elif c.kind == "soc":
                out.append(clarabel.SecondOrderConeT(c.dim))
            elif c.kind == "psd":
                out.append(clarabel.PSDTriangleConeT(c.size))
            else:  # pragma: no cover
                raise ValueError(f"unknown cone {c.kind}")
        return out

    def solve_once(self, problem: ConicProblem, label="default", overrides=None, deadline: Deadline | None = None,
                   first_seconds: float = 0.0, stop_by: Deadline | None = None):
        """One Clarabel call: (solution or None, :class:`Attempt`).

        With a ``deadline``, the call is not made when the time left is shorter than Clarabel's
        uninterruptible start -- set-up, initial point and one iteration, predicted by
        :data:`sospoly.budget.CLARABEL_TIME_MODEL` from the program's size, or ``first_seconds`` (what an
        earlier attempt on the same program measured) when larger -- and Clarabel's ``time_limit`` is the
        time left minus that start, so its last iteration ends before the deadline.  ``stop_by`` (default: the
        ``deadline``): no iteration is begun that is predicted to end past it
        (:func:`sospoly.solvers.interrupt.solve_interruptibly`: an attempt so stopped has status ``time_limit``).
        A call not made returns (None, an attempt with status ``time_limit`` and 0 iterations)."""
        import clarabel

        n = problem.n_cols
        overrides = dict(overrides or {})
        psd = [c.size for c in problem.cones if c.kind == "psd"]
        if overrides.get("direct_solve_method") == "qdldl" and max(psd, default=0) > QDLDL_MAX_PSD_SIDE:
            del overrides["direct_solve_method"]
            label = label if label.endswith("/faer") else f"{label}/faer"
        remaining = None if deadline is None else deadline.remaining()
        if remaining is not None:
            first = max(CLARABEL_TIME_MODEL.first_iteration(psd, problem.n_rows), first_seconds)
            if remaining < first:
                return None, Attempt(label, RawStatus.TIME_LIMIT,
                                     f"not started: {remaining:.3g} s left, set-up and one iteration take "
                                     f"~{first:.3g} s", 0, 0.0)
            overrides["time_limit"] = max(remaining - first, 1e-3)
        _check_native_memory(problem)
        P = sp.csc_matrix((n, n))
        t0 = time.perf_counter()
        try:
            solver = clarabel.DefaultSolver(P, np.asarray(problem.q, float), sp.csc_matrix(problem.A),
                                            np.asarray(problem.b, float), self._cones(problem),
                                            self._settings(overrides))
            t_setup = time.perf_counter() - t0
            sol = solve_interruptibly(solver, deadline if stop_by is None else stop_by)
        except (KeyboardInterrupt, SystemExit):
            raise
        except BaseException as exc:  # pyo3 PanicException derives from BaseException
            att = Attempt(label, RawStatus.FAILED, f"exception: {type(exc).__name__}: {exc}"[:200], 0,
                          time.perf_counter() - t0)
            return None, att
        seconds = time.perf_counter() - t0
        CLARABEL_TIME_MODEL.observe(psd, problem.n_rows, t_setup, seconds - t_setup, int(sol.iterations))
        status_name = str(sol.status).split(".")[-1]
        raw = RawStatus.TIME_LIMIT if stopped_for_time(sol) else _CLARABEL_MAP.get(status_name, RawStatus.FAILED)
        start = t_setup + 2.0 * (seconds - t_setup) / (int(sol.iterations) + 1)
        att = Attempt(label, raw, status_name, int(sol.iterations), seconds, min(start, seconds))
        return sol, att

    def solve(self, problem: ConicProblem, accept=None, retry: bool = True,
              deadline: Deadline | None = None) -> ConicSolution:
        """Solve, walking the retry chain while the outcome is a numerical failure.

        ``accept(x, z) -> bool`` is an optional a-posteriori check: a SOLVED attempt
        that fails it is treated like a numerical failure and the chain continues.
        ``retry=False`` makes a single attempt (bisection steps, where "unknown" is
        simply treated as "not certified").  ``deadline`` becomes Clarabel's ``time_limit``
        (less its uninterruptible start, see :meth:`solve_once`); no attempt starts that cannot
        finish its first iteration before the deadline, and the chain then ends with status
        ``time_limit`` and the last attempt's iterate (if any).  The retries after a failed first full attempt
        share a budget of iterations (``Tolerances.retry_budget_*``: Clarabel's ``max_iter``, not a time limit, so
        that the outcome does not depend on the machine's load); one it stops is a failed attempt and ends the
        chain.  Only the caller's ``deadline`` stops an iteration predicted to end
        past it (:meth:`solve_once`'s ``stop_by``), and only it keeps a retry from starting that cannot finish
        before it: one that the time left does not give the attempt it repeats (:func:`_repeat_seconds`; review
        32b M1: a qdldl retry's uninterruptible first factorisation took 5-10 s, 8x faer's, past a 20 s limit).
        """
        attempts = []
        last = provisional = budget = None     # budget: the retries' iterations left (None before the first full)
        first_seconds = whole = 0.0  # the longest start measured so far; the last whole attempt (_repeat_seconds)
        for label, overrides in self._chain(problem, retry):
            if budget is not None and budget <= 0:     # (before the deadline: a spent budget is no time limit)
                attempts.append(Attempt(label, RawStatus.FAILED, "not started (retry budget spent)", 0, 0.0))
                break
            if deadline is not None and deadline.expired or not _fits(deadline, whole):
                attempts.append(Attempt(label, RawStatus.TIME_LIMIT, "time limit reached" if deadline.expired else
                                        f"not started: the attempt it repeats took {whole:.3g} s", 0, 0.0))
                return _kept(provisional, attempts) or self._time_limit(last, attempts)
            capped = overrides if budget is None else {**overrides, "max_iter": min(budget, self._max_iter(overrides))}
            sol, att = self.solve_once(problem, label, capped, deadline, first_seconds,
                                       stop_by=deadline or _NO_DEADLINE)
            attempts.append(att)
            if budget is not None:
                budget -= att.iterations
                attempts[-1], spent = _budget_label(att, capped["max_iter"] < self._max_iter(overrides)
                                                    and att.iterations >= capped["max_iter"])
                if spent:
                    break                                # the retries' budget, not the caller's limit
            if budget is None and not _provisional(overrides):
                budget = self._retry_budget(problem, att.iterations)
            if sol is None:
                if att.raw_status == RawStatus.TIME_LIMIT:
                    return _kept(provisional, attempts) or self._time_limit(last, attempts)
                first_seconds = max(first_seconds, att.seconds)     # an exception: all of it was uninterruptible
                continue
            first_seconds = max(first_seconds, att.start_seconds)
            whole = _repeat_seconds(att)
            x, z = np.asarray(sol.x, float), np.asarray(sol.z, float)
            last = ConicSolution(att.raw_status, x, z, float(sol.obj_val), float(sol.obj_val_dual), tuple(attempts))
            if att.raw_status == RawStatus.TIME_LIMIT:
                return _kept(provisional, attempts) or last
            if _provisional(overrides) and att.raw_status != RawStatus.SOLVED:
                if att.raw_status == RawStatus.ALMOST_SOLVED and self.tolerances.accept_inaccurate and \
                        (accept is None or accept(x, z)):
                    provisional = last                   # kept in case the refined attempts run out of time
                continue                                 # CLARABEL_FAST_CHAIN: the refined attempts decide
            if att.raw_status == RawStatus.DUAL_INFEASIBLE and retry and \
                    not check_unbounded_ray(problem, x, self.tolerances)[0]:
                continue                                 # an unchecked ray is a numerical failure: next settings
            if att.raw_status == RawStatus.PRIMAL_INFEASIBLE and provisional is not None:
                return _kept(provisional, attempts)      # an accepted iterate says feasible: the unchecked claim loses
            if att.raw_status == RawStatus.PRIMAL_INFEASIBLE and retry and \
                    not check_infeasibility(problem, z, self.tolerances)[0]:
                continue                                 # an unchecked certificate is a numerical failure too
            if att.raw_status in (RawStatus.PRIMAL_INFEASIBLE, RawStatus.DUAL_INFEASIBLE):
                return last
            if att.raw_status == RawStatus.SOLVED and (accept is None or accept(x, z)):
                return last
            if att.raw_status == RawStatus.ALMOST_SOLVED and self.tolerances.accept_inaccurate and \
                    (accept is None or accept(x, z)):
                return last                              # the caller makes the bound rigorous (Tolerances)
        if provisional is not None or last is None:              # the accepted answer over a rejected last one
            return _kept(provisional, attempts) or ConicSolution(RawStatus.FAILED, None, None, None, None,
                                                                 tuple(attempts))
        return ConicSolution(last.raw_status, last.x, last.z, last.primal_objective, last.dual_objective,
                             tuple(attempts))

    def _retry_budget(self, problem: ConicProblem, first: int) -> int:
        """The iterations the retries share after a first full attempt of ``first`` iterations (:class:`Tolerances`:
        counted in iterations, with ``retry_budget_seconds`` converted by the program's reference iteration time,
        so that the chain's outcome does not depend on the machine's load)."""
        tol = self.tolerances
        psd = [c.size for c in problem.cones if c.kind == "psd"]
        per = CLARABEL_TIME_MODEL.reference_iteration(psd, problem.n_rows)
        n = max(tol.retry_budget_iterations, tol.retry_budget_share * first, tol.retry_budget_seconds / per)
        return int(math.ceil(min(n, 1e9)))

    def _max_iter(self, overrides) -> int:
        """Clarabel's iteration limit of an attempt with ``overrides``."""
        return int({**self.settings, **overrides}.get("max_iter", self.tolerances.solver_max_iter))

    def _chain(self, problem: ConicProblem, retry: bool):
        """The retry chain for ``problem``: qdldl dropped where a PSD block is too large for it
        (:data:`QDLDL_MAX_PSD_SIDE`), and an attempt whose settings repeat an earlier one's skipped (it
        would fail the same way at the same cost)."""
        big = max((c.size for c in problem.cones if c.kind == "psd"), default=0) > QDLDL_MAX_PSD_SIDE

        def effective(label, overrides):
            overrides = dict(overrides)
            if big and overrides.get("direct_solve_method") == "qdldl":
                del overrides["direct_solve_method"]
                label = f"{label}/faer"
            return label, overrides

        known = {**dict(CLARABEL_FAST_CHAIN), **dict(CLARABEL_SPLIT_CHAIN), **dict(self.retry_chain)}
        seen = [effective(lb, ov)[1] for lb, ov in known.items() if lb in self.skip]
        chain = [c for c in (self.retry_chain if retry else self.retry_chain[:1]) if c[0] not in self.skip]
        for label, overrides in (effective(*c) for c in chain):
            if overrides in seen:
                continue
            seen.append(overrides)
            yield label, overrides

    @staticmethod
    def _time_limit(last: ConicSolution | None, attempts: list) -> ConicSolution:
        """Status ``time_limit`` with the last attempt's iterate (the caller judges what it certifies)."""
        if last is None:
            return ConicSolution(RawStatus.TIME_LIMIT, None, None, None, None, tuple(attempts))
        return ConicSolution(RawStatus.TIME_LIMIT, last.x, last.z, last.primal_objective, last.dual_objective,
                             tuple(attempts))


#: above this estimated cost (sum over PSD blocks of m n^3) the IPM forms its Schur
#: complement from sparse A and the svec Kronecker operator instead of dense matmuls.
IPM_DENSE_LIMIT = 3e6


class IpmBackend:
    """:mod:`sospoly.solvers.ipm` first, ``fallback`` (default Clarabel) when it does not converge
    or ``accept`` rejects its answer."""

    name = "ipm"

    def __init__(self, tolerances: Tolerances = DEFAULT_TOLERANCES, fallback=None):
        self.tolerances = as_tolerances(tolerances)
        self.fallback = fallback if fallback is not None else ClarabelBackend(self.tolerances)

    def solve(self, problem: ConicProblem, accept=None, retry: bool = True,
              deadline: Deadline | None = None, *, take_stalled: bool = False) -> ConicSolution:
        """``take_stalled``: a stalled iterate that meets :func:`ipm_almost_solved` is the answer (status
        ALMOST_SOLVED, only with ``Tolerances.accept_inaccurate``) instead of a fall-back."""
        from .ipm import IPM_LEVEL, ipm_solve_batch, ipm_solve_sparse, layout_of
        from .level import active_level, stop_threshold

        t0 = time.perf_counter()
        try:
            lay = layout_of(problem.cones)
        except ValueError as exc:   # cones the IPM does not handle: straight to the fallback
            att = Attempt("ipm", RawStatus.FAILED, str(exc)[:200], 0, 0.0)
            sol = None
        else:
            if deadline is not None and deadline.expired:    # no set-up past the deadline; the fallback ends it
                att = Attempt(IPM_LABEL, RawStatus.TIME_LIMIT, "time limit reached", 0, 0.0)
                fb = self.fallback.solve(problem, accept=accept, retry=retry, deadline=deadline)
                return dataclasses.replace(fb, attempts=(att,) + tuple(fb.attempts))
            m = problem.n_cols
            taken: list = []                    # a stalled moment-form iterate taken as almost solved (sparse path)
            if sum(m * n ** 3 for n in lay.sizes) <= IPM_DENSE_LIMIT:
                res = ipm_solve_batch(problem.A.toarray()[None], problem.b[None], problem.q, problem.cones,
                                      self.tolerances, deadline=deadline)
            else:
                stop_at = stop_threshold(active_level(), problem.objective_sign, problem.objective_offset) \
                    if self.tolerances.accept_inaccurate else None

                def almost(r):
                    if self.tolerances.accept_inaccurate and ipm_almost_solved(problem, r, self.tolerances):
                        taken.append(r)
                        return True
                    return False
                res = ipm_solve_sparse(problem.A, problem.b, problem.q, problem.cones, self.tolerances,
                                       deadline=deadline, stop_at=stop_at, almost=almost)
            ok = bool(res.converged[0])
            x, z = res.x[0], res.z[0]
            raw = RawStatus.SOLVED if ok else RawStatus.FAILED
            if not ok and ((taken and taken[-1] is res) or (
                    take_stalled and self.tolerances.accept_inaccurate and res.reason[0] == IPM_STALLED
                    and ipm_almost_solved(problem, res, self.tolerances))):
                ok, raw = True, RawStatus.ALMOST_SOLVED          # the caller makes the bound rigorous
            if not ok and self.tolerances.accept_inaccurate and res.reason[0] == IPM_LEVEL:
                ok, raw = True, RawStatus.ALMOST_SOLVED          # an iterate at the caller's level (.level)
            if ok and accept is not None and not accept(x, z):
                ok, why = False, "certificate check failed"
            else:
                why = ("converged" if raw == RawStatus.SOLVED else res.reason[0]) if ok else res.reason[0]
            att = Attempt(IPM_LABEL, raw if ok else RawStatus.FAILED, why, int(res.iterations[0]),
                          time.perf_counter() - t0)
            sol = ConicSolution(raw, x, z, float(res.primal_objective[0]),
                                float(res.dual_objective[0]), (att,)) if ok else None
        if sol is not None:
            return sol
        fb = self.fallback.solve(problem, accept=accept, retry=retry, deadline=deadline)
        return dataclasses.replace(fb, attempts=(att,) + tuple(fb.attempts))


#: the label of the interior-point attempts (:class:`Attempt`), and its reason for an iterate that stopped improving.
IPM_LABEL = "ipm"
IPM_STALLED = "stalled"
#: a stalled IPM iterate counts as "almost solved" (:data:`RawStatus.ALMOST_SOLVED`, taken only with
#: ``Tolerances.accept_inaccurate``, whose callers make the bound rigorous) when its relative gap is at most
#: ``Tolerances.gap_rel / IPM_ALMOST_GAP_SHARE`` (the solver's gap takes at most a tenth of what the certificate
#: rule allows, so it does not cost a certificate Clarabel's 1e-9 answer would give) and its relative residuals
#: at most IPM_ALMOST_FEAS.  Measured on dense degree-2 programs with mixed regions (N = 6..30, one Gram block of
#: side 20-105 beside the regions' scalar multipliers): the IPM stalls at gaps of 4e-9..3e-8 from N = 10 (2.6e-6
#: on one 6-view program), primal residuals ~1e-15, dual ~1.5e-8, 2-3x faster than Clarabel from N = 16
#: (benchmarks/RESULTS.md, issue #22, wave 8).
IPM_ALMOST_GAP_SHARE = 10.0
IPM_ALMOST_FEAS = 1e-6


def ipm_almost_solved(problem: ConicProblem, res, tolerances: Tolerances = DEFAULT_TOLERANCES) -> bool:
    """Is the IPM's (first) iterate ``res`` (:class:`~sospoly.solvers.ipm.IpmResult`) of ``problem`` "almost
    solved": |p - d| <= (gap_rel / IPM_ALMOST_GAP_SHARE) max(1, min(|p|, |d|)) for the primal and dual objectives
    p, d, and ||b - A x - s||_inf <= IPM_ALMOST_FEAS (1 + ||b||_inf), ||A^T z + q||_inf <= IPM_ALMOST_FEAS
    (1 + ||q||_inf)?"""
    x, z, s = res.x[0], res.z[0], res.s[0]
    p, d = float(res.primal_objective[0]), float(res.dual_objective[0])
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(z)) and np.isfinite(p) and np.isfinite(d)):
        return False
    b, q = np.asarray(problem.b, float), np.asarray(problem.q, float)
    r_p = np.max(np.abs(b - problem.A @ x - s), initial=0.0) / (1.0 + np.max(np.abs(b), initial=0.0))
    r_d = np.max(np.abs(problem.A.T @ z + q), initial=0.0) / (1.0 + np.max(np.abs(q), initial=0.0))
    return bool(tolerances.solver_gap_within(p, d, IPM_ALMOST_GAP_SHARE) and r_p <= IPM_ALMOST_FEAS and
                r_d <= IPM_ALMOST_FEAS)


#: below this estimated IPM cost (sum over PSD blocks of m n^3) one Clarabel call is faster
#: than the IPM's per-iteration Python overhead (measured crossover ~5e4: Corollary 1 at
#: delta = 2 with N = 5 -> 6 ms Clarabel vs 21 ms IPM; N = 8 -> 42 ms vs 22 ms).
AUTO_IPM_MIN_COST = 5e4
#: the same crossover for one Gram block beside scalar blocks (no moment form: the IPM's sparse Schur operator).
#: Measured on Corollary 1's degree-2 programs with mixed regions (CPU, one thread; Clarabel's split-cliques
#: chain against the IPM): N = 6 (cost 1.7e5) 0.01 vs 0.03 s, N = 10 (2.4e6) 0.06 vs 0.08 s, N = 16 (2.9e7)
#: 0.34 vs 0.17 s, N = 30 (3.9e8) 3.7-5.3 vs 1.4-1.9 s.
AUTO_IPM_MIN_COST_SCALARS = 1e7
#: the IPM's working set (~3 m sum_k n_k^2 + m^2 floats, see sospoly.budget) above which AutoBackend
#: goes to Clarabel directly (whose memory grows with sum_k L_k^2 instead); one value with the budget's model.
AUTO_IPM_MAX_BYTES = _AUTO_IPM_MAX_BYTES


def _repeat_seconds(att: Attempt) -> float:
    """Seconds the next attempt of the chain is taken to need at least after ``att`` ended by itself: its whole
    time, scaled to ``RETRY_MIN_ITERATIONS`` iterations where it took more (0 after a time limit).  A retry is no
    faster per iteration (qdldl is the slower factorisation, refinement and regularisation add work) and needs
    about as many iterations; one that cannot finish only spends the caller's time."""
    if att.raw_status == RawStatus.TIME_LIMIT:
        return 0.0
    return att.seconds * min(1.0, RETRY_MIN_ITERATIONS / max(att.iterations, 1))


def _fits(deadline: Deadline | None, seconds: float) -> bool:
    """Is there ``seconds`` left before ``deadline`` (None, or no end: always)?"""
    remaining = None if deadline is None else deadline.remaining()
    return remaining is None or remaining >= seconds


def _budget_label(att: Attempt, cut: bool) -> tuple[Attempt, bool]:
    """(attempt, chain ends) of a retry: one the budget's ``max_iter`` stopped says so -- MaxIterations becomes a
    failed attempt and ends the chain; another unsolved answer at the cap (AlmostSolved: Clarabel's reduced tolerances
    met) keeps its status."""
    if not cut or att.raw_status == RawStatus.SOLVED:
        return att, False
    spent = att.solver_status == "MaxIterations"
    return dataclasses.replace(att, raw_status=RawStatus.FAILED if spent else att.raw_status,
                               solver_status=f"{att.solver_status} (retry budget spent)"), spent


def _kept(provisional: ConicSolution | None, attempts: list) -> ConicSolution | None:
    """The provisional attempt's "almost solved" answer (accepted by the caller's check, with
    ``accept_inaccurate``) when the refined attempts after it ran out of time or ended without an accepted answer
    (failed, or almost solved and rejected: review 3 of wave 18): its caller makes the bound rigorous,
    as for any such answer (a 30-view views program ended AlmostSolved without refinement in 10 s, then the refined
    attempt ran to the 60 s limit and the step reported no bound at all, review 18); None without one."""
    if provisional is None:
        return None
    return ConicSolution(RawStatus.ALMOST_SOLVED, provisional.x, provisional.z, provisional.primal_objective,
                         provisional.dual_objective, tuple(attempts))


def _provisional(overrides: dict) -> bool:
    """An attempt without iterative refinement (:data:`CLARABEL_FAST_CHAIN`): only SOLVED is final."""
    return overrides.get("iterative_refinement_enable") is False


class AutoBackend:
    """Clarabel for small single problems, :class:`IpmBackend` (with Clarabel fallback) above
    ``AUTO_IPM_MIN_COST``; ``clarabel_chain`` the retry chain of both (e.g. :data:`CLARABEL_FAST_CHAIN`),
    ``skip`` the labels of attempts already made on the program (Clarabel's: :class:`ClarabelBackend`; ``"ipm"``:
    straight to Clarabel);
    batches of equal structure should use
    :meth:`sospoly.solvers.compiled_solve.CompiledPsatz.solve_batch` instead."""

    name = "auto"

    def __init__(self, tolerances: Tolerances = DEFAULT_TOLERANCES, clarabel_chain=CLARABEL_RETRY_CHAIN, *,
                 skip=()):
        self.clarabel = ClarabelBackend(as_tolerances(tolerances), retry_chain=clarabel_chain, skip=skip)
        self.ipm = IpmBackend(self.clarabel.tolerances, fallback=self.clarabel)
        self.skip_ipm = IPM_LABEL in {str(label).split("/")[0] for label in skip}   # it repeats its answer

    def solve(self, problem: ConicProblem, accept=None, retry: bool = True,
              deadline: Deadline | None = None) -> ConicSolution:
        from .ipm import layout_of

        try:
            lay = layout_of(problem.cones)
        except ValueError:
            return self.clarabel.solve(problem, accept=accept, retry=retry, deadline=deadline)
        m = problem.n_cols
        cost = sum(m * n ** 3 for n in lay.sizes)
        ipm_bytes = 8.0 * (3.0 * m * sum(n * n for n in lay.sizes) + float(m) ** 2)
        # the IPM's Schur complement is dense over every column: it pays off for one dominant Gram block (the
        # moment form; beside it only scalar blocks, e.g. the constant multipliers of a degree-2 certificate's
        # inequalities), not for programs of many blocks, whose sparsity Clarabel's factorisation keeps
        # beside scalar blocks the IPM's iterates stall short of its own stopping rule (measured: every degree-2
        # program with regions): only worth it where an "almost solved" answer is taken (accept_inaccurate)
        scalars = len(lay.sizes) > 1
        single = not scalars or (sum(1 for n in lay.sizes if n > 1) == 1 and self.clarabel.tolerances.accept_inaccurate)
        least = AUTO_IPM_MIN_COST_SCALARS if scalars else AUTO_IPM_MIN_COST
        if single and not self.skip_ipm and least <= cost and ipm_bytes <= AUTO_IPM_MAX_BYTES:
            return self.ipm.solve(problem, accept=accept, retry=retry, deadline=deadline, take_stalled=scalars)
        return self.clarabel.solve(problem, accept=accept, retry=retry, deadline=deadline)


def get_backend(backend, tolerances: Tolerances = DEFAULT_TOLERANCES):
    """Resolve a back-end given by object, or by name ``"clarabel"`` / ``"ipm"`` / ``"auto"`` / ``"cvxpy"`` /
    ``"cvxpy:SCS"``.

    Raises
    ------
    ValueError
        An unknown back-end name, or a solver name cvxpy does not know (``"cvxpy:NOSUCH"``).
    ImportError
        cvxpy not installed, or a solver cvxpy knows but which is not installed (``"cvxpy:MOSEK"``).
    """
    tolerances = as_tolerances(tolerances)
    if backend is None:
        return ClarabelBackend(tolerances)
    if isinstance(backend, str):
        name, _, solver = backend.partition(":")
        if name == "clarabel":
            return ClarabelBackend(tolerances)
        if name == "cvxpy":
            from .cvxpy_backend import CvxpyBackend

            check_cvxpy_solver(solver or None)
            return CvxpyBackend(solver or None, tolerances)
        if name == "ipm":
            return IpmBackend(tolerances)
        if name == "auto":
            return AutoBackend(tolerances)
        raise ValueError(f"unknown backend {backend!r}: use 'clarabel', 'ipm', 'auto', 'cvxpy' or 'cvxpy:<SOLVER>'")
    if not hasattr(backend, "solve"):
        raise TypeError("backend must be a name or an object with a solve(problem, accept) method")
    return backend


def __getattr__(name: str):
    """``CvxpyBackend`` lives in :mod:`.cvxpy_backend` (which builds on this module's classes)."""
    if name == "CvxpyBackend":
        from .cvxpy_backend import CvxpyBackend
        return CvxpyBackend
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
