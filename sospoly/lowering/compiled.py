"""Compile once, solve many: a Positivstellensatz *structure* lowered once.

A :class:`~sospoly.certificates.psatz.PsatzStructure` is an SOS program whose data -- the
coefficient vector theta of :class:`~sospoly.certificates.psatz.DataSlots`, and for a free
multiplier the level c -- enter as parameters.  Its conic data (A, b) of
:func:`sospoly.lowering.conic.lower` are therefore *affine* in them:

    A = A_0 + sum_t theta_t A_t + c A_c,      b = b_0 + sum_t theta_t b_t + c b_c.

:class:`CompiledPsatz` lowers the structure once and stores the maps theta -> A.data (on the
fixed sparsity pattern of A) and theta -> b as sparse matrices.  A new instance then costs one
coefficient look-up and two sparse mat-vecs (:meth:`CompiledPsatz.problem_from_theta`), and a
batch of instances one sparse mat-mat (:meth:`CompiledPsatz.solve_batch`, which solves them
together with the batched interior-point method of :mod:`sospoly.solvers.ipm`).

Parameters of the structure (see :mod:`sospoly.certificates.psatz`): ``f:t`` feeds theta entry t
of f; ``m:t`` is the t-th term *slot* of every constrained polynomial at once (the multipliers own
disjoint columns, so the slot's matrix splits by column block into the matrix of each polynomial's
t-th coefficient); ``c`` is the GEVP level of a free multiplier.  Results go through the same
a-posteriori checks (:func:`sospoly.solvers.solve.solve_program`).

:class:`PsatzCache` keeps compiled structures keyed by the structure, or by a caller's key (e.g. a
triangulation's (N, region types, method, delta)); a key whose instance falls outside the cached
supports is recompiled on the union of the supports.
"""
from __future__ import annotations

import dataclasses
import time
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..budget import as_budget, check_deadline
from ..certificates.psatz import (DataSlots, Multiplier, PsatzProblem, PsatzStructure, StructureMismatch, as_multiplier,
                                  certificate_shape, check_size, checked_inputs, fixed_q_for, psatz_structure)
from ..solvers.backends import Attempt, ConicSolution, RawStatus, get_backend
from ..solvers.ipm import ipm_solve_batch, layout_of
from ..solvers.solve import LowerBound, lower_bound_of, solve_program
from ..status import SolveStatus
from ..tolerances import DEFAULT_TOLERANCES, Tolerances, as_tolerances
from .conic import ConicProblem, GramForm, lower

__all__ = ["BatchBounds", "CompiledPsatz", "CompiledInstance", "PsatzCache", "compile_psatz", "structure_for",
           "StructureMismatch"]


@dataclass(frozen=True, eq=False)
class CompiledInstance:
    """One instance's numbers in a compiled structure: theta and its conic problem
    (:func:`sospoly.solve_psatz` accepts it like a :class:`~sospoly.certificates.psatz.PsatzProblem`)."""
    compiled: CompiledPsatz
    theta: np.ndarray
    problem: ConicProblem

    @property
    def structure(self) -> PsatzStructure:
        return self.compiled.structure

    @property
    def n_lmivar(self) -> int:
        return self.compiled.n_lmivar

    @property
    def u(self):
        return self.compiled.structure.u

    @property
    def degree(self) -> int:
        return self.compiled.structure.degree

    @property
    def gens(self) -> tuple:
        return self.compiled.structure.gens

    @property
    def shape(self):
        return self.compiled.structure.shape

    def as_problem(self) -> PsatzProblem:
        """The :class:`~sospoly.certificates.psatz.PsatzProblem` of these numbers (polynomials rebuilt)."""
        f, eq, ineq = self.compiled.structure.slots.polynomials(self.theta)
        return PsatzProblem(self.compiled.structure, self.theta, f, eq, ineq)


@dataclass(frozen=True)
class BatchBounds:
    """Vectorised outcome of :meth:`CompiledPsatz.batch_bounds` (leading axis: the instances).

    ``ok`` is True where the batched interior-point method converged *and* the returned Gram
    matrix passes :meth:`sospoly.Tolerances.psd_accepts` (the rule of
    :func:`sospoly.solvers.solve.check_certificate`); the image form's coefficient identity holds by
    construction.  Only there is ``lower_bound`` a certified bound; ``reason`` says why not
    elsewhere.  ``eigenvalues`` / ``eigenvectors`` are those of ``gram`` (ascending), for
    extraction (identity where the IPM did not converge).  ``gram_error`` bounds the rounding of
    ``gram`` (||G_computed - G(x)||_2) for :func:`sospoly.analysis.rigor.image_form_stack_margin`: the
    caller, who knows a region holding a minimiser, makes ``lower_bound`` rigorous with it."""
    lower_bound: np.ndarray     # (B,)
    gram: np.ndarray            # (B, n, n)
    eigenvalues: np.ndarray     # (B, n)
    eigenvectors: np.ndarray    # (B, n, n)
    ok: np.ndarray              # (B,) bool
    iterations: np.ndarray      # (B,) int
    reason: tuple               # (B,) str
    gram_error: np.ndarray | None = None    # (B,)


def _param_source(name: str, col_owner: np.ndarray, cols: np.ndarray, offsets: np.ndarray, n_theta: int):
    """theta index (n_theta for the GEVP level c) of each entry of a parameter's matrix."""
    if name == "c":
        return np.full(cols.size, n_theta, np.int64)
    kind, t = name.split(":")
    t = int(t)
    if kind == "f":
        return np.full(cols.size, offsets[0] + t, np.int64)
    return offsets[col_owner[cols]] + t        # "m:t": the column's owner polynomial


class CompiledPsatz:
    """A Positivstellensatz structure lowered once (see module docstring)."""

    def __init__(self, structure: PsatzStructure, form: GramForm = GramForm.IMAGE):
        self.structure = structure
        self.form = GramForm(form)
        slots = structure.slots
        prog = structure.program
        conic = lower(prog, self.form)
        check_deadline("compiling the program")
        self._template = conic
        offsets = slots.offsets
        n_theta = slots.n_theta
        self.n_theta = n_theta
        n_ext = n_theta + (1 if structure.free else 0)
        # column -> index of the constrained polynomial (1 + k) whose multiplier owns it
        col_owner = np.zeros(conic.n_cols, np.int64)
        names = [f"r{k}" for k in range(slots.n_eq)] + [f"s{k}" for k in range(slots.n_ineq)]
        for pi, name in enumerate(names, start=1):
            col_owner[prog.block(name).slice] = pi
        A0 = conic.A.tocoo()
        rows, cols, vals, src = [A0.row], [A0.col], [A0.data], [np.full(A0.nnz, -1)]
        nrows = conic.n_rows
        brows, bsrc, bvals = [], [], []
        for name, (Ak, bk) in conic.params.items():
            Ak = Ak.tocoo()
            rows.append(Ak.row), cols.append(Ak.col), vals.append(Ak.data)
            src.append(_param_source(name, col_owner, Ak.col, offsets, n_theta))
            nz = np.nonzero(bk)[0]
            if nz.size:
                if name.startswith("m:"):  # pragma: no cover - multiplier terms are linear
                    raise AssertionError("a multiplier term produced constant data")
                brows.append(nz), bvals.append(bk[nz])
                bsrc.append(_param_source(name, col_owner, np.zeros(nz.size, np.int64), offsets, n_theta))
        rows, cols, vals, src = map(np.concatenate, (rows, cols, vals, src))
        check_deadline("compiling the program")
        key = cols.astype(np.int64) * nrows + rows
        ukey, pos = np.unique(key, return_inverse=True)
        self._pat_rows = (ukey % nrows).astype(np.int64)
        self._pat_cols = (ukey // nrows).astype(np.int64)
        self._indptr = np.searchsorted(self._pat_cols, np.arange(conic.n_cols + 1)).astype(np.int64)
        base = src < 0
        self._A0 = np.bincount(pos[base], vals[base], minlength=ukey.size)
        self._DA = sp.csr_matrix((vals[~base], (pos[~base], src[~base])), shape=(ukey.size, n_ext))
        self._b0 = conic.b.copy()
        self._Db = sp.csr_matrix((np.concatenate(bvals), (np.concatenate(brows), np.concatenate(bsrc))),
                                 shape=(nrows, n_ext)) if brows else sp.csr_matrix((nrows, n_ext))

    # ------------------------------------------------------------------ structure
    @property
    def slots(self) -> DataSlots:
        return self.structure.slots

    @property
    def program(self):
        return self.structure.program

    @property
    def u(self):
        return self.structure.u

    @property
    def degree(self) -> int:
        return self.structure.degree

    @property
    def gens(self) -> tuple:
        return self.structure.gens

    @property
    def n_lmivar(self) -> int:
        return self.structure.n_lmivar

    @property
    def template(self) -> ConicProblem:
        """The lowered program with every parameter at 0 (its cones, objective and block map)."""
        return self._template

    def contains(self, f, eq=(), ineq=()) -> bool:
        """Do the instance's supports lie in this structure's (and degrees match)?"""
        try:
            self.theta(f, eq, ineq)
        except StructureMismatch:
            return False
        return True

    def theta(self, f, eq=(), ineq=()) -> np.ndarray:
        """The coefficient vector theta of an instance (raises :class:`StructureMismatch`)."""
        return self.slots.theta(f, eq, ineq)

    def _check_theta(self, theta) -> np.ndarray:
        theta = np.asarray(theta, float)
        if theta.ndim == 1:
            theta = theta[None]
        if theta.ndim != 2 or theta.shape[1] != self.n_theta:
            raise StructureMismatch(f"theta must have {self.n_theta} entries per instance, got shape {theta.shape}")
        if not np.all(np.isfinite(theta)):
            raise ValueError("theta (the polynomial coefficients) contains NaN or inf")
        return theta

    def _extended(self, theta: np.ndarray, c) -> np.ndarray:
        if not self.structure.free:
            if c is not None:
                raise ValueError("the level c is a parameter of free-multiplier structures only")
            return theta
        c = np.zeros(theta.shape[0]) if c is None else np.broadcast_to(np.asarray(c, float), theta.shape[:1])
        return np.hstack([theta, c[:, None]])

    # ------------------------------------------------------------------ numbers
    def problem_from_theta(self, theta, c: float | None = None) -> ConicProblem:
        """The conic problem of one instance given its coefficient vector (and the GEVP level c)."""
        th = self._extended(self._check_theta(theta)[:1], c)[0]
        data = self._A0 + self._DA @ th
        A = sp.csc_matrix((data, self._pat_rows, self._indptr), shape=self._template.A.shape)
        return dataclasses.replace(self._template, A=A, b=self._b0 + self._Db @ th, params={})

    def instantiate(self, f, eq=(), ineq=()) -> CompiledInstance:
        return self.bind(self.theta(f, eq, ineq))

    def bind(self, theta) -> CompiledInstance:
        """The instance of a coefficient vector theta."""
        th = self._check_theta(theta)[0]
        return CompiledInstance(self, th, self.problem_from_theta(th))

    def dense_batch(self, thetas) -> tuple[np.ndarray, np.ndarray]:
        """(A, b) of a batch as dense arrays (B, rows, cols), (B, rows)."""
        th = self._extended(self._check_theta(thetas), None)
        data = self._A0[None] + (self._DA @ th.T).T
        A = np.zeros((th.shape[0],) + self._template.A.shape)
        A[:, self._pat_rows, self._pat_cols] = data
        b = self._b0[None] + (self._Db @ th.T).T
        return A, b

    # ------------------------------------------------------------------ solving
    def _trivially_unbounded(self) -> bool:
        s = self.slots
        return not s.n_eq and not s.n_ineq and s.degrees[0] % 2 == 1

    def solve(self, f, eq=(), ineq=(), *, backend=None, tolerances: Tolerances = DEFAULT_TOLERANCES,
              deadline=None) -> LowerBound:
        """c* of one instance: :func:`sospoly.solve_psatz`'s answer for the fixed multiplier."""
        return self.solve_theta(self.theta(f, eq, ineq), backend=backend, tolerances=tolerances, deadline=deadline)

    def solve_theta(self, theta, *, backend=None, tolerances: Tolerances = DEFAULT_TOLERANCES,
                    problem: ConicProblem | None = None, deadline=None) -> LowerBound:
        tolerances = as_tolerances(tolerances)
        if self.structure.free:
            raise ValueError("a free-multiplier structure is solved by bisection (sospoly.solve_psatz)")
        if self._trivially_unbounded():
            return LowerBound(SolveStatus.INFEASIBLE, None, None, None, "f has odd degree and there are no "
                              "constraints: f is unbounded below")
        problem = self.problem_from_theta(theta) if problem is None else problem
        sol = solve_program(self.program, backend, self.form, tolerances, problem=problem, deadline=deadline)
        return lower_bound_of(sol, self.degree)

    def solve_batch(self, instances=None, *, thetas=None, fallback=None,
                    tolerances: Tolerances = DEFAULT_TOLERANCES) -> list[LowerBound]:
        """Solve many instances together with the batched interior-point method.

        ``instances``: (f, eq, ineq) triples, or ``thetas`` (B, n_theta) directly.  Each
        instance's answer passes the same a-posteriori checks as a single solve; an
        instance the batch did not converge on, or whose certificate fails the checks,
        is re-solved by ``fallback`` (default Clarabel) and its ``solution.attempts``
        record both.
        """
        tolerances = as_tolerances(tolerances)
        if thetas is None:
            thetas = np.array([self.theta(*inst) for inst in instances]) if instances else np.zeros((0, self.n_theta))
        th = self._check_theta(thetas) if len(thetas) else np.zeros((0, self.n_theta))
        if th.shape[0] == 0:
            return []
        if self._trivially_unbounded():
            return [self.solve_theta(t, tolerances=tolerances) for t in th]
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
            out.append(lower_bound_of(sol, self.degree))
        return out

    def batch_bounds(self, thetas, tolerances: Tolerances = DEFAULT_TOLERANCES) -> BatchBounds:
        """Lower bounds of many instances with no per-instance Python: the batched
        interior-point method, the Gram matrices from its x (G = smat(b - A x)), their
        eigendecomposition and the PSD-margin check, all on stacks.  No fallback: callers
        re-solve the instances with ``ok = False`` one by one (:meth:`solve_theta`).
        Programs with a single PSD block and no other cone (e.g. equality-constrained
        programs in the image form) only."""
        from ..algebra.svec import smat

        tolerances = as_tolerances(tolerances)
        t = self._template
        lay = layout_of(t.cones)
        if lay.p or len(lay.sizes) != 1:
            raise ValueError("batch_bounds handles programs with one PSD block and no other cone")
        n = lay.sizes[0]
        th = self._check_theta(thetas)
        A, b = self.dense_batch(th)
        res = ipm_solve_batch(A, b, t.q, t.cones, tolerances)
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
        return BatchBounds(c_lb, G, lam, V, res.converged & psd, res.iterations, reason, gram_error)


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


def structure_for(f, eq=(), ineq=(), degree=None, multiplier=Multiplier.FIXED, gens=None, *, sparsity="none",
                  low_degree=None, slots: DataSlots | None = None, budget=None) -> PsatzStructure:
    """The structure :func:`sospoly.build_psatz` builds for these polynomials (on ``slots`` when given,
    e.g. the union of several instances' supports), checked against ``budget`` the same way."""
    budget = as_budget(budget)
    f, eq, ineq, gens, degree = checked_inputs(f, eq, ineq, degree, gens, budget.max_gram_side)
    multiplier = as_multiplier(multiplier)
    shape = certificate_shape(sparsity, gens, degree, f, eq, ineq, low_degree=low_degree,
                              max_gram_side=budget.max_gram_side)
    q = fixed_q_for(multiplier, gens, degree, f, shape.is_dense)
    check_size(shape, budget, q is None, len(gens), degree, f.degree)
    return psatz_structure(slots if slots is not None else DataSlots.of(f, eq, ineq, gens), degree, shape, q)


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
        slots = DataSlots.of(f, eq, ineq, gens)
        k = None if key is None else ("user", key, tuple(gens), int(degree), GramForm(form).value)
        if k is not None:
            comp = self._store.get(k)
            if comp is not None:
                if comp.slots.contains(slots):
                    self._store.move_to_end(k)
                    return comp, comp.theta(f, eq, ineq)
                old = comp.slots
                if (old.gens, old.n_eq, old.n_ineq, old.degrees) == (slots.gens, slots.n_eq, slots.n_ineq,
                                                                     slots.degrees):
                    slots = old.union(slots)        # same structure, larger support: compile on the union
        structure = structure_for(f, eq, ineq, degree, multiplier, gens, sparsity=sparsity, low_degree=low_degree,
                                  slots=slots, budget=budget)
        comp = self.compiled(structure, form, key=k)
        return comp, comp.theta(f, eq, ineq)

