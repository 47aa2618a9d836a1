"""Solving compiled Positivstellensatz structures: one instance, a batch, or the vectorised bounds.

:class:`CompiledPsatz` is a :class:`~sospoly.lowering.compiled.LoweredPsatz` (a structure lowered once,
its conic data affine in the instance's coefficients theta) that a solver consumes:
:meth:`~CompiledPsatz.solve_theta` solves one instance with a back-end and the a-posteriori checks of
:func:`sospoly.solvers.solve.solve_program`; :meth:`~CompiledPsatz.solve_batch` solves many together with the
batched interior-point method of :mod:`sospoly.solvers.ipm` (a back-end re-solves what the batch did not
certify); :meth:`~CompiledPsatz.batch_bounds` gives the bounds of a batch with no per-instance Python.
:func:`compile_psatz` and :class:`PsatzCache` make (and keep) compiled structures.

The lowering layer never imports this module: a solver consumes a lowered problem.
"""
from __future__ import annotations

import dataclasses
import time
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from ..budget import as_budget
from ..certificates.psatz import (DataSlots, Multiplier, PsatzStructure, StructureMismatch, as_multiplier, check_size,
                                  checked_inputs)
from ..lowering.compiled import LoweredPsatz, structure_for
from ..lowering.conic import ConicProblem, GramForm
from ..status import SolveStatus
from ..tolerances import DEFAULT_TOLERANCES, Tolerances, as_tolerances
from .backends import Attempt, ConicSolution, RawStatus, get_backend
from .ipm import ipm_solve_batch, layout_of
from .psatz_claims import as_certificate_data, balanced_recheck, proven_empty, proven_level
from .solve import LowerBound, lower_bound_of, solve_program

__all__ = ["BatchBounds", "CompiledPsatz", "PsatzCache", "compile_psatz"]


@dataclass(frozen=True)
class BatchBounds:
    """Vectorised outcome of :meth:`CompiledPsatz.batch_bounds` (leading axis: the instances).

    ``ok`` is True where the batched interior-point method converged *and* the returned Gram
    matrix passes :meth:`sospoly.Tolerances.psd_accepts` (the rule of
    :func:`sospoly.solvers.solve.check_certificate`); the image form's coefficient identity holds by
    construction.  Only there is ``lower_bound`` the checked numerical c* (like ``prove=False`` of
    :meth:`CompiledPsatz.solve_theta`: the accepted Gram defect may lift it above the minimum at large scales,
    review 26a F5); ``reason`` says why not elsewhere.  ``eigenvalues`` / ``eigenvectors`` are those of
    ``gram`` (ascending), for extraction (identity where the IPM did not converge).  ``gram_error`` bounds the
    rounding of ``gram`` (||G_computed - G(x)||_2) for :func:`sospoly.analysis.rigor.image_form_stack_margin`: the
    caller, who knows a region holding a minimiser, makes ``lower_bound`` rigorous with it."""
    lower_bound: np.ndarray     # (B,)
    gram: np.ndarray            # (B, n, n)
    eigenvalues: np.ndarray     # (B, n)
    eigenvectors: np.ndarray    # (B, n, n)
    ok: np.ndarray              # (B,) bool
    iterations: np.ndarray      # (B,) int
    reason: tuple               # (B,) str
    gram_error: np.ndarray | None = None    # (B,)
    x: np.ndarray | None = None             # (B, columns) the IPM's decision vectors (the program's variables first)


class CompiledPsatz(LoweredPsatz):
    """A Positivstellensatz structure lowered once (:class:`~sospoly.lowering.compiled.LoweredPsatz`), with the
    solvers of its instances (see module docstring)."""

    def _trivially_unbounded(self) -> bool:
        s = self.slots
        return not s.n_eq and not s.n_ineq and s.degrees[0] > 0 and s.degrees[0] % 2 == 1     # (f = 0: degree -1)

    def solve(self, f, eq=(), ineq=(), *, backend=None, tolerances: Tolerances = DEFAULT_TOLERANCES,
              deadline=None, prove: bool = True) -> LowerBound:
        """c* of one instance: :func:`sospoly.solve_psatz`'s answer for the fixed multiplier."""
        return self.solve_theta(self.theta(f, eq, ineq), backend=backend, tolerances=tolerances, deadline=deadline,
                                prove=prove)

    def solve_theta(self, theta, *, backend=None, tolerances: Tolerances = DEFAULT_TOLERANCES,
                    problem: ConicProblem | None = None, deadline=None, prove: bool = True,
                    recheck: bool = True) -> LowerBound:
        """One instance's :class:`~sospoly.solvers.psatz_claims.PsatzBound`: with ``prove`` (the default) its
        ``lower_bound`` is the solver's c* proven for every v (:func:`~sospoly.solvers.psatz_claims.proven_level`:
        OPTIMAL at c* - m, m <= 1e-7 of the scale; INACCURATE with a weaker proven bound; UNPROVEN with none) and
        c* is ``relaxation``; ``prove=False`` gives the numerical c* as ``lower_bound`` (status OPTIMAL meaning
        "the solver's certificate passed the a-posteriori checks", not a proof: for callers that prove the bound
        themselves, such as :func:`sospoly.minimize` and tritools' rigour stage).  "The set is empty" (UNBOUNDED)
        is claimed only with a proven ray (:func:`~sospoly.solvers.psatz_claims.proven_empty`) in both modes;
        with ``prove`` (and ``recheck``), INFEASIBLE (or an unproven ray) is re-decided on the exactly balanced
        program (:func:`~sospoly.solvers.psatz_claims.balanced_recheck`).  With ``prove=False`` no further solve is
        made: the solver's checked INFEASIBLE is the caller's to judge (minimize solves balanced data already)."""
        tolerances = as_tolerances(tolerances)
        if self.structure.free:
            raise ValueError("a free-multiplier structure is solved by bisection (sospoly.solve_psatz)")
        if self._trivially_unbounded():
            return LowerBound(SolveStatus.INFEASIBLE, None, None, None, "f has odd degree and there are no "
                              "constraints: f is unbounded below")
        problem = self.problem_from_theta(theta) if problem is None else problem
        sol = solve_program(self.program, backend, self.form, tolerances, problem=problem, deadline=deadline)
        lb = self._claim(theta, lower_bound_of(sol, self.degree), problem, prove, tolerances, deadline)
        if recheck and prove:
            def again(ps):
                return CompiledPsatz(ps.structure, self.form).solve_theta(
                    ps.theta, backend=backend, tolerances=tolerances, deadline=deadline, recheck=False)
            lb = balanced_recheck(self.structure, theta, lb, again, prove)
        return lb

    def _claim(self, theta, lb: LowerBound, problem: ConicProblem, prove: bool, tolerances,
               deadline=None) -> LowerBound:
        """The claims of :meth:`solve_theta` (:mod:`sospoly.solvers.psatz_claims`)."""
        if lb.status not in (SolveStatus.OPTIMAL, SolveStatus.UNBOUNDED):
            return lb
        data = as_certificate_data(None, self.structure, np.asarray(theta, float).reshape(-1))
        if lb.status == SolveStatus.UNBOUNDED:
            return proven_empty(data, lb, problem, deadline)
        return proven_level(data, lb, tolerances, deadline) if prove else lb

    def solve_batch(self, instances=None, *, thetas=None, fallback=None,
                    tolerances: Tolerances = DEFAULT_TOLERANCES, prove: bool = True) -> list[LowerBound]:
        """Solve many instances together with the batched interior-point method.

        ``instances``: (f, eq, ineq) triples, or ``thetas`` (B, n_theta) directly.  Each
        instance's answer passes the same a-posteriori checks as a single solve; an
        instance the batch did not converge on, or whose certificate fails the checks,
        is re-solved by ``fallback`` (default Clarabel) and its ``solution.attempts``
        record both.  ``prove``: the claims of :meth:`solve_theta`.
        """
        tolerances = as_tolerances(tolerances)
        if thetas is None:
            thetas = np.array([self.theta(*inst) for inst in instances]) if instances else np.zeros((0, self.n_theta))
        th = self._check_theta(thetas) if len(thetas) else np.zeros((0, self.n_theta))
        if th.shape[0] == 0:
            return []
        if self._trivially_unbounded():
            return [self.solve_theta(t, tolerances=tolerances, prove=prove) for t in th]
        t0 = time.perf_counter()
        A, b = self.dense_batch(th)
        res = ipm_solve_batch(A, b, self._template.q, self._template.cones, tolerances)
        per = (time.perf_counter() - t0) / th.shape[0]
        fb = get_backend(fallback, tolerances)
        out = []
        for i in range(th.shape[0]):
            att = Attempt("ipm-batch", RawStatus.SOLVED if res.converged[i] else RawStatus.FAILED,
                          "converged" if res.converged[i] else res.reason[i], int(res.iterations[i]), per)
            pre = ConicSolution(att.raw_status, res.x[i], res.z[i], float(res.primal_objective[i]),
                                float(res.dual_objective[i]), (att,)) if res.converged[i] else None
            problem = self.problem_from_theta(th[i])
            sol = solve_program(self.program, _Presolved(pre, att, fb), self.form, tolerances, problem=problem)
            lb = self._claim(th[i], lower_bound_of(sol, self.degree), problem, prove, tolerances)
            out.append(balanced_recheck(self.structure, th[i], lb, lambda ps: CompiledPsatz(
                ps.structure, self.form).solve_theta(ps.theta, tolerances=tolerances, recheck=False), True)
                       if prove else lb)
        return out

    def batch_bounds(self, thetas, tolerances: Tolerances = DEFAULT_TOLERANCES, deadline=None) -> BatchBounds:
        """Lower bounds of many instances with no per-instance Python: the batched
        interior-point method, the Gram matrices from its x (G = smat(b - A x)), their
        eigendecomposition and the PSD-margin check, all on stacks.  No fallback: callers
        re-solve the instances with ``ok = False`` one by one (:meth:`solve_theta`).
        Programs with a single PSD block and no other cone (e.g. equality-constrained
        programs in the image form) only.  ``deadline`` (a :class:`sospoly.budget.Deadline`): the IPM stops one
        predicted iteration before it; the instances it leaves are not ``ok`` (reason: the time limit)."""
        from ..algebra.svec import smat

        tolerances = as_tolerances(tolerances)
        t = self._template
        lay = layout_of(t.cones)
        if lay.p or len(lay.sizes) != 1:
            raise ValueError("batch_bounds handles programs with one PSD block and no other cone")
        n = lay.sizes[0]
        th = self._check_theta(thetas)
        A, b = self.dense_batch(th)
        res = ipm_solve_batch(A, b, t.q, t.cones, tolerances, deadline=deadline)
        G = smat(b - np.einsum("brm,bm->br", A, res.x), n)
        # rounding of b - A x: |error_r| <= gamma_(m+1) (|b_r| + sum_k |A_rk| |x_k|); smat scales off-diagonal
        # svec entries by 1/sqrt(2), so ||Delta G||_2 <= ||Delta G||_F <= ||error||_2
        m = A.shape[2]
        size = np.abs(b) + np.einsum("brm,bm->br", np.abs(A), np.abs(res.x))
        eps = np.finfo(float).eps
        gram_error = (m + 1) * eps / (1 - (m + 1) * eps) * np.linalg.norm(size, axis=1) \
            + eps * np.linalg.norm(G, axis=(1, 2))                   # and the division by sqrt(2) in smat
        lam, V = np.linalg.eigh(np.where(res.converged[:, None, None], G, np.eye(n)))
        psd = tolerances.psd_accepts(lam[:, 0], np.abs(G).max(axis=(1, 2)))
        reason = tuple("" if (c and p) else (f"ipm: {r}" if not c else
                                             f"Gram lambda_min {l0:.3g} below the PSD margin")
                       for c, p, r, l0 in zip(res.converged, psd, res.reason, lam[:, 0]))
        c_lb = t.objective_sign * (res.x @ t.q) + t.objective_offset
        return BatchBounds(c_lb, G, lam, V, res.converged & psd, res.iterations, reason, gram_error, res.x)


class _Presolved:
    """Backend adaptor: an answer computed elsewhere (a batch), else the fallback backend."""

    def __init__(self, solution: ConicSolution | None, attempt: Attempt, fallback):
        self.solution, self.attempt, self.fallback = solution, attempt, fallback

    def solve(self, problem, accept=None, retry=True, deadline=None) -> ConicSolution:
        s = self.solution
        if s is not None and (accept is None or accept(s.x, s.z)):
            return s
        att = self.attempt if s is None else Attempt(self.attempt.label, RawStatus.ALMOST_SOLVED,
                                                     "certificate check failed", self.attempt.iterations,
                                                     self.attempt.seconds)
        fb = self.fallback.solve(problem, accept=accept, retry=retry, deadline=deadline)
        return dataclasses.replace(fb, attempts=(att,) + tuple(fb.attempts))


def compile_psatz(f, eq=(), ineq=(), degree=None, multiplier=Multiplier.FIXED, form=GramForm.IMAGE,
                  gens=None, *, sparsity="none", low_degree=None, budget=None) -> CompiledPsatz:
    """Compile the structure of (f, eq, ineq) at ``degree`` (see :class:`CompiledPsatz`)."""
    if as_multiplier(multiplier) == Multiplier.FREE:
        raise ValueError("compile_psatz compiles fixed multipliers; the free-q GEVP is solved by "
                         "sospoly.solve_psatz (bisection over a compiled free structure)")
    return CompiledPsatz(structure_for(f, eq, ineq, degree, multiplier, gens, sparsity=sparsity,
                                       low_degree=low_degree, budget=budget), form)


class PsatzCache:
    """Compiled structures by key, least recently used dropped beyond ``maxsize``."""

    def __init__(self, maxsize: int = 64):
        self.maxsize = int(maxsize)
        self._store: OrderedDict = OrderedDict()
        self.compiles = 0

    def __len__(self) -> int:
        return len(self._store)

    def clear(self) -> None:
        self._store.clear()

    def compiled(self, structure: PsatzStructure, form=GramForm.IMAGE, key=None) -> CompiledPsatz:
        """The compiled form of ``structure`` (cached under ``key``, default the structure's own key)."""
        k = ("structure", structure.key, GramForm(form).value) if key is None else key
        comp = self._store.get(k)
        if comp is None or comp.structure.key != structure.key:
            comp = CompiledPsatz(structure, form)
            self.compiles += 1
            self._store[k] = comp
        self._store.move_to_end(k)
        while len(self._store) > self.maxsize:
            self._store.popitem(last=False)
        return comp

    def get(self, f, eq=(), ineq=(), degree=None, multiplier=Multiplier.FIXED, form=GramForm.IMAGE, gens=None,
            key=None, *, sparsity="none", low_degree=None, budget=None) -> tuple[CompiledPsatz, np.ndarray]:
        """(a compiled structure that contains this instance, the instance's theta); compiled on a miss.

        With ``key`` given (any hashable describing the structure), an instance whose supports fall
        outside the cached entry's is compiled on the union of both."""
        eq, ineq = tuple(eq), tuple(ineq)
        f, eq, ineq, gens, degree = checked_inputs(f, eq, ineq, degree, gens, as_budget(budget).max_gram_side)
        k = None if key is None else ("user", key, tuple(gens), int(degree), GramForm(form).value,
                                      _token(multiplier), _token(sparsity), _token(low_degree))
        if k is not None:
            comp = self._store.get(k)
            if comp is not None:
                theta = _theta_within(comp, f, eq, ineq)     # every term inside the entry's support: a hit
                if theta is not None:
                    _sized(comp, budget, len(gens), degree, f.degree, form)
                    self._store.move_to_end(k)
                    return comp, theta
        slots = DataSlots.of(f, eq, ineq, gens)
        if k is not None:
            comp = self._store.get(k)
            if comp is not None:
                if comp.slots.contains(slots):   # a degree that differs: sized, then theta raises, as before
                    _sized(comp, budget, len(gens), degree, f.degree, form)
                    return comp, comp.theta(f, eq, ineq)
                old = comp.slots
                if (old.gens, old.n_eq, old.n_ineq, old.degrees) == (slots.gens, slots.n_eq, slots.n_ineq,
                                                                     slots.degrees):
                    slots = old.union(slots)        # same structure, larger support: compile on the union
        structure = structure_for(f, eq, ineq, degree, multiplier, gens, sparsity=sparsity, low_degree=low_degree,
                                  slots=slots, budget=budget, form=form)
        comp = self.compiled(structure, form, key=k)
        return comp, comp.theta(f, eq, ineq)


def _token(value):
    """A hashable stand-in of a structure argument for :meth:`PsatzCache.get`'s key: the value itself, or its repr
    (a user's key now also holds the multiplier, the sparsity and the low degree: a hit had returned the structure
    of another multiplier, review 26a F9)."""
    try:
        hash(value)
        return value
    except TypeError:
        return repr(value)


def _sized(comp: CompiledPsatz, budget, n_gens: int, degree: int, f_degree: int, form) -> None:
    """A cached structure, compiled under another budget perhaps, sized against this call's (raises as
    :func:`check_size`)."""
    st = comp.structure
    check_size(st.shape, as_budget(budget), st.free, n_gens, degree, f_degree, slots=comp.slots, q=st.q,
               image_form=GramForm(form) == GramForm.IMAGE)


def _theta_within(comp: CompiledPsatz, f, eq, ineq):
    """The instance's theta in ``comp``'s slots, or None where a term lies outside them (or a degree differs):
    :meth:`DataSlots.theta` raises :class:`StructureMismatch` exactly where :meth:`DataSlots.contains` of the
    instance's own slots is False, or the degree differs -- one pass instead of building the slots and
    searching them twice (~0.7 ms of every compiled solve of a three-view Theorem 1 program)."""
    try:
        return comp.theta(f, eq, ineq)
    except StructureMismatch:
        return None
