"""Compile once, solve many: a Positivstellensatz *structure* lowered once.

For the fixed-multiplier program of :mod:`sospoly.certificates.psatz` (SPEC §5)

    u(v) = q(v) (f(v) - c) + r(v)^T g(v) - s(v)^T h(v)   SOS,  s_k SOS,  max c,

the conic data (A, b) of :func:`sospoly.lowering.conic.lower` is *affine in the coefficient
vector* theta = (coef f, coef g_1, ..., coef h_m) once the supports of f, g_k, h_k,
the degree delta, the variables and q are fixed:

    A = A_0 + sum_t theta_t A_t,      b = b_0 + sum_t theta_t b_t.

:class:`CompiledPsatz` builds the program once with theta as *parameters*
(``param_terms`` of the u constraint: q m_t for the terms of f, r_k m_t for those of
g_k, -s_k m_t for those of h_k), lowers it once, and stores the maps
theta -> A.data (on the fixed sparsity pattern of A) and theta -> b as sparse
matrices.  A new instance then costs one coefficient look-up and two sparse
mat-vecs (:meth:`CompiledPsatz.instantiate`), and a batch of instances one
sparse mat-mat (:meth:`CompiledPsatz.solve_batch`, which solves them together with
the batched interior-point method of :mod:`sospoly.solvers.ipm`).

The multiplier degrees (deg r_k = delta - deg g_k, ...) come from the template's
degrees; an instance is accepted when each of its polynomials has its support inside
the template's (zero coefficients are allowed), and the lowered program is then
exactly :func:`~sospoly.certificates.psatz.build_psatz`'s whenever the instance's degrees equal the
template's.  Results go through the same a-posteriori checks
(:func:`sospoly.solvers.solve.solve_program`).  The free-q GEVP is compiled by
:class:`sospoly.solvers.gevp.CompiledGevp` instead.

:class:`PsatzCache` keeps compiled structures keyed by the structure (number of
variables, degree, supports, multiplier, Gram form), or by a caller's key (e.g. a
triangulation's (N, region types, method, delta)); a key whose instance falls
outside the cached supports is recompiled on the union of the supports.
"""
from __future__ import annotations

import dataclasses
import time
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..solvers.backends import Attempt, ConicSolution, RawStatus, get_backend
from ..algebra.basis import MonomialIndex
from .conic import ConicProblem, GramForm, lower
from ..solvers.ipm import _smat_batch, ipm_solve_batch, layout_of
from ..algebra.linpoly import LinPoly
from ..minimize import LowerBound, lower_bound_of
from ..algebra.polynomial import Polynomial
from ..certificates.program import SOSProgram
from ..certificates.psatz import Multiplier, _as_multiplier, _checked_inputs, _fixed_q, common_gens, delta_min
from ..solvers.solve import ProgramSolution, solve_program
from ..status import SolveStatus
from ..tolerances import DEFAULT_TOLERANCES, Tolerances

__all__ = ["BatchBounds", "CompiledPsatz", "CompiledInstance", "PsatzCache", "compile_psatz", "StructureMismatch",
           "DEFAULT_CACHE"]


class StructureMismatch(ValueError):
    """An instance does not fit a compiled structure (names what differs)."""


def _support(p: Polynomial) -> np.ndarray:
    E = p.exponents()
    return E[np.lexsort(E.T[::-1])] if E.shape[0] else E


@dataclass(frozen=True)
class CompiledInstance:
    """One instance's numbers in a compiled structure: theta and its conic problem
    (:func:`sospoly.solve_psatz` accepts it like a :class:`~sospoly.certificates.psatz.PsatzProblem`)."""
    compiled: "CompiledPsatz"
    theta: np.ndarray
    problem: ConicProblem

    @property
    def n_lmivar(self) -> int:
        return self.compiled.n_lmivar

    @property
    def u(self):
        return self.compiled.u


@dataclass(frozen=True)
class BatchBounds:
    """Vectorised outcome of :meth:`CompiledPsatz.batch_bounds` (leading axis: the instances).

    ``ok`` is True where the batched interior-point method converged *and* the returned
    Gram matrix passes :func:`sospoly.solvers.solve.check_certificate`'s PSD-margin rule
    (lambda_min(G) >= -psd_margin * max(1, max|G_ij|)); the image form's coefficient
    identity holds by construction.  Only there is ``lower_bound`` a certified bound;
    ``reason`` says why not elsewhere.  ``eigenvalues`` / ``eigenvectors`` are those of
    ``gram`` (ascending), for extraction (identity where the IPM did not converge)."""
    lower_bound: np.ndarray     # (B,)
    gram: np.ndarray            # (B, n, n)
    eigenvalues: np.ndarray     # (B, n)
    eigenvectors: np.ndarray    # (B, n, n)
    ok: np.ndarray              # (B,) bool
    iterations: np.ndarray      # (B,) int
    reason: tuple               # (B,) str


class CompiledPsatz:
    """A fixed-multiplier Positivstellensatz structure lowered once (see module docstring).

    Parameters are template polynomials (only their supports, and degrees, matter),
    the even degree delta, the multiplier (``"fixed"``, a positive number or an SOS
    Polynomial q) and the Gram form.
    """

    def __init__(self, f, eq=(), ineq=(), degree: int | None = None, multiplier=Multiplier.FIXED,
                 form: GramForm = GramForm.IMAGE, gens=None):
        f, eq, ineq, gens, degree = _checked_inputs(f, eq, ineq, degree, gens)
        multiplier = _as_multiplier(multiplier)
        if multiplier == Multiplier.FREE:
            raise ValueError("CompiledPsatz compiles fixed multipliers; the free-q GEVP is compiled by "
                             "sospoly.solvers.gevp.CompiledGevp")
        q = _fixed_q(multiplier, gens, degree, f)
        self.gens, self.degree, self.q, self.form = gens, degree, q, GramForm(form)
        self.multiplier = multiplier
        self.supports = tuple(_support(p) for p in (f,) + eq + ineq)
        self.degrees = tuple(p.degree for p in (f,) + eq + ineq)
        self.n_eq, self.n_ineq = len(eq), len(ineq)
        self._template_polys = (f,) + eq + ineq

        # ---- the parametric program, blocks in build_psatz's order (c, r_k, s_k)
        t0 = time.perf_counter()
        prog = SOSProgram(gens)
        c = prog.scalar("c")
        mults = []
        for k, g in enumerate(eq):
            mults.append(prog.free_poly(degree - g.degree, name=f"r{k}"))
        for k, h in enumerate(ineq):
            mults.append(-1.0 * prog.sos_poly(degree - h.degree, name=f"s{k}"))
        # One parameter per term of f (q m_t, constant: b only) and one per term *slot* t of the
        # multiplied polynomials (sum_k mult_k m_{k,t}): the multipliers own disjoint columns, so
        # each slot's A_t splits by column block into the A of every theta_{k,t}.
        qlin = LinPoly.from_polynomial(q, gens)
        params = {}
        offsets = np.cumsum([0] + [E.shape[0] for E in self.supports])
        for t, e in enumerate(self.supports[0]):
            params[f"f:{t}"] = qlin * Polynomial._raw(gens, {tuple(int(k) for k in e): 1.0})
        n_slots = max([E.shape[0] for E in self.supports[1:]], default=0)
        for t in range(n_slots):
            # sum_k mult_k * m_{k,t}: shifting a LinPoly's exponents by a monomial keeps its
            # rows distinct, so the parts are concatenated and merged once
            parts = [(mults[pi - 1], self.supports[pi][t]) for pi in range(1, len(self.supports))
                     if t < self.supports[pi].shape[0]]
            Es, cs, rs, cl, vs, off = [], [], [], [], [], 0
            for M, e in parts:
                Es.append(M.E + e), cs.append(M.const), rs.append(M.rows + off), cl.append(M.cols)
                vs.append(M.vals)
                off += M.E.shape[0]
            term = LinPoly(gens, np.vstack(Es), np.concatenate(cs), np.concatenate(rs), np.concatenate(cl),
                           np.concatenate(vs))
            params[f"m:{t}"] = term
        self.program = prog
        self.u = prog.add_sos(-1.0 * (c * q), degree=degree, name="u", param_terms=params)
        prog.maximize(c)
        conic = lower(prog, self.form)
        self._template = conic
        self.n_theta = int(offsets[-1])
        self._offsets = offsets
        # column -> index of the polynomial (1 + k) whose multiplier owns it
        col_poly = np.full(conic.n_cols, -1, np.int64)
        for pi, blk in enumerate(prog.blocks[1:], start=1):
            col_poly[blk.slice] = pi

        # ---- theta -> A.data / b maps on the union sparsity pattern of A
        A0 = conic.A.tocoo()
        rows, cols, vals, src = [A0.row], [A0.col], [A0.data], [np.full(A0.nnz, -1)]
        nrows = conic.n_rows
        brows, bsrc, bvals = [], [], []
        for name, (Ak, bk) in conic.params.items():
            kind, t = name.split(":")
            t = int(t)
            Ak = Ak.tocoo()
            if kind == "f":
                nz = np.nonzero(bk)[0]
                brows.append(nz), bsrc.append(np.full(nz.size, offsets[0] + t)), bvals.append(bk[nz])
                if Ak.nnz:  # pragma: no cover - q m_t is constant
                    raise AssertionError("a term of f produced decision-dependent data")
                continue
            if np.any(bk != 0):  # pragma: no cover - multiplier terms are linear
                raise AssertionError("a multiplier term produced constant data")
            pis = col_poly[Ak.col]
            rows.append(Ak.row), cols.append(Ak.col), vals.append(Ak.data), src.append(offsets[pis] + t)
        n = len(gens)
        rows, cols, vals, src = map(np.concatenate, (rows, cols, vals, src))
        key = cols.astype(np.int64) * nrows + rows
        ukey, pos = np.unique(key, return_inverse=True)
        self._pat_rows = (ukey % nrows).astype(np.int64)
        self._pat_cols = (ukey // nrows).astype(np.int64)
        ncols = conic.n_cols
        self._indptr = np.searchsorted(self._pat_cols, np.arange(ncols + 1)).astype(np.int64)
        base = src < 0
        self._A0 = np.bincount(pos[base], vals[base], minlength=ukey.size)
        self._DA = sp.csr_matrix((vals[~base], (pos[~base], src[~base])), shape=(ukey.size, self.n_theta))
        self._b0 = conic.b.copy()
        self._Db = sp.csr_matrix((np.concatenate(bvals), (np.concatenate(brows), np.concatenate(bsrc))),
                                 shape=(nrows, self.n_theta)) if brows else sp.csr_matrix((nrows, self.n_theta))
        self._index = MonomialIndex(np.hstack([np.repeat(np.arange(len(self.supports)), np.diff(offsets))[:, None],
                                               np.vstack(self.supports) if self.n_theta else np.zeros((0, n), int)]))
        self._theta_memo = None
        self.compile_seconds = time.perf_counter() - t0

    # ------------------------------------------------------------------ structure
    @property
    def n_lmivar(self) -> int:
        return self.program.n_lmivar()

    def contains(self, f, eq=(), ineq=()) -> bool:
        """Do the instance's supports lie in this structure's (and degrees match)?"""
        try:
            self.theta(f, eq, ineq)
        except StructureMismatch:
            return False
        return True

    def theta(self, f, eq=(), ineq=()) -> np.ndarray:
        """The coefficient vector theta of an instance (raises :class:`StructureMismatch`).

        The last instance's theta is remembered by the identity of its polynomial objects
        (Polynomials are not modified in place), so the containment test of a cache look-up
        and the instantiation that follows read the coefficients once."""
        eq, ineq = tuple(eq), tuple(ineq)
        memo = self._theta_memo
        if memo is not None and len(memo[0]) == 1 + len(eq) + len(ineq) and \
                all(a is b for a, b in zip(memo[0], (f,) + eq + ineq)):
            return memo[1].copy()
        th = self._theta(f, eq, ineq)
        self._theta_memo = ((f,) + eq + ineq, th.copy())
        return th

    def _theta(self, f, eq, ineq) -> np.ndarray:
        if len(eq) != self.n_eq or len(ineq) != self.n_ineq:
            raise StructureMismatch(f"the structure has {self.n_eq} equalities and {self.n_ineq} inequalities; "
                                    f"the instance has {len(eq)} and {len(ineq)}")
        polys = (f,) + eq + ineq
        Es, cs, ids = [], [], []
        for pi, p in enumerate(polys):
            what = self._name_of(pi)
            if not isinstance(p, Polynomial):
                raise TypeError(f"{what} must be a sospoly Polynomial, got {type(p).__name__}")
            if p.gens != self.gens:
                try:
                    p = p.with_gens(self.gens)
                except (ValueError, KeyError) as exc:
                    raise StructureMismatch(f"{what} has variables {p.gens}, the structure {self.gens}") from exc
            if p.degree != self.degrees[pi] and not p.is_zero:
                raise StructureMismatch(f"{what} has degree {p.degree}, the structure {self.degrees[pi]}")
            Es.append(p.exponents())
            cs.append(p.coefficients())
            ids.append(np.full(len(p.terms), pi))
        E = np.hstack([np.concatenate(ids)[:, None], np.vstack(Es)])
        idx = self._index.find(E, missing_ok=True)
        if np.any(idx < 0):
            bad = E[np.argmax(idx < 0)]
            raise StructureMismatch(f"{self._name_of(int(bad[0]))} has a term with exponent {tuple(int(k) for k in bad[1:])} outside the "
                                    "compiled support")
        th = np.zeros(self.n_theta)
        th[idx] = np.concatenate(cs)
        return th

    def _name_of(self, pi: int) -> str:
        """The name of polynomial ``pi`` of (f, eq..., ineq...) in messages."""
        return "f" if pi == 0 else (f"eq[{pi - 1}]" if pi <= self.n_eq else f"ineq[{pi - 1 - self.n_eq}]")

    def _check_theta(self, theta) -> np.ndarray:
        theta = np.asarray(theta, float)
        if theta.ndim == 1:
            theta = theta[None]
        if theta.ndim != 2 or theta.shape[1] != self.n_theta:
            raise StructureMismatch(f"theta must have {self.n_theta} entries per instance, got shape {theta.shape}")
        if not np.all(np.isfinite(theta)):
            raise ValueError("theta (the polynomial coefficients) contains NaN or inf")
        return theta

    # ------------------------------------------------------------------ numbers
    def problem_from_theta(self, theta) -> ConicProblem:
        """The conic problem of one instance given its coefficient vector."""
        th = self._check_theta(theta)[0]
        data = self._A0 + self._DA @ th
        A = sp.csc_matrix((data, self._pat_rows, self._indptr), shape=self._template.A.shape)
        return dataclasses.replace(self._template, A=A, b=self._b0 + self._Db @ th, params={})

    def instantiate(self, f, eq=(), ineq=()) -> CompiledInstance:
        th = self.theta(f, eq, ineq)
        return CompiledInstance(self, th, self.problem_from_theta(th))

    def bind(self, theta) -> CompiledInstance:
        """The instance of a coefficient vector theta."""
        th = self._check_theta(theta)[0]
        return CompiledInstance(self, th, self.problem_from_theta(th))

    def dense_batch(self, thetas) -> tuple[np.ndarray, np.ndarray]:
        """(A, b) of a batch as dense arrays (B, rows, cols), (B, rows)."""
        th = self._check_theta(thetas)
        data = self._A0[None] + (self._DA @ th.T).T
        A = np.zeros((th.shape[0],) + self._template.A.shape)
        A[:, self._pat_rows, self._pat_cols] = data
        b = self._b0[None] + (self._Db @ th.T).T
        return A, b

    # ------------------------------------------------------------------ solving
    def _lower_bound(self, sol: ProgramSolution) -> LowerBound:
        return lower_bound_of(sol, self.degree)

    def _trivially_unbounded(self) -> bool:
        return not self.n_eq and not self.n_ineq and self.degrees[0] % 2 == 1

    def solve(self, f, eq=(), ineq=(), *, backend=None, tolerances: Tolerances = DEFAULT_TOLERANCES) -> LowerBound:
        """c* of one instance: :func:`sospoly.solve_psatz`'s answer for the fixed multiplier."""
        return self.solve_theta(self.theta(f, eq, ineq), backend=backend, tolerances=tolerances)

    def solve_theta(self, theta, *, backend=None, tolerances: Tolerances = DEFAULT_TOLERANCES,
                    problem: ConicProblem | None = None) -> LowerBound:
        if self._trivially_unbounded():
            return LowerBound(SolveStatus.INFEASIBLE, None, None, None, "f has odd degree and there are no "
                              "constraints: f is unbounded below")
        problem = self.problem_from_theta(theta) if problem is None else problem
        return self._lower_bound(solve_program(self.program, backend, self.form, tolerances, problem=problem))

    def solve_batch(self, instances=None, *, thetas=None, fallback=None,
                    tolerances: Tolerances = DEFAULT_TOLERANCES) -> list[LowerBound]:
        """Solve many instances together with the batched interior-point method.

        ``instances``: (f, eq, ineq) triples, or ``thetas`` (B, n_theta) directly.  Each
        instance's answer passes the same a-posteriori checks as a single solve; an
        instance the batch did not converge on, or whose certificate fails the checks,
        is re-solved by ``fallback`` (default Clarabel) and its ``solution.attempts``
        record both.
        """
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
            out.append(self._lower_bound(sol))
        return out


    def batch_bounds(self, thetas, tolerances: Tolerances = DEFAULT_TOLERANCES) -> BatchBounds:
        """Lower bounds of many instances with no per-instance Python: the batched
        interior-point method, the Gram matrices from its x (G = smat(b - A x)), their
        eigendecomposition and the PSD-margin check, all on stacks.  No fallback: callers
        re-solve the instances with ``ok = False`` one by one (:meth:`solve_theta`).
        Programs with a single PSD block and no other cone (e.g. equality-constrained
        programs in the image form) only."""
        t = self._template
        lay = layout_of(t.cones)
        if lay.p or len(lay.sizes) != 1:
            raise ValueError("batch_bounds handles programs with one PSD block and no other cone")
        n = lay.sizes[0]
        th = self._check_theta(thetas)
        A, b = self.dense_batch(th)
        res = ipm_solve_batch(A, b, t.q, t.cones, tolerances)
        G = _smat_batch(b - np.einsum("brm,bm->br", A, res.x), n)
        lam, V = np.linalg.eigh(np.where(res.converged[:, None, None], G, np.eye(n)))
        psd = lam[:, 0] >= -tolerances.psd_margin * np.maximum(1.0, np.abs(G).max(axis=(1, 2)))
        reason = tuple("" if (c and p) else (f"ipm: {r}" if not c else
                                             f"Gram lambda_min {l0:.3g} below the PSD margin")
                       for c, p, r, l0 in zip(res.converged, psd, res.reason, lam[:, 0]))
        c_lb = t.objective_sign * (res.x @ t.q) + t.objective_offset
        return BatchBounds(c_lb, G, lam, V, res.converged & psd, res.iterations, reason)

class _Presolved:
    """Backend adaptor: an answer computed elsewhere (a batch), else the fallback backend."""

    def __init__(self, solution: ConicSolution | None, attempt: Attempt, fallback):
        self.solution, self.attempt, self.fallback = solution, attempt, fallback

    def solve(self, problem, accept=None, retry=True) -> ConicSolution:
        s = self.solution
        if s is not None and (accept is None or accept(s.x, s.z)):
            return s
        att = self.attempt if s is None else Attempt(self.attempt.label, RawStatus.ALMOST_SOLVED,
                                                     "certificate check failed", self.attempt.iterations,
                                                     self.attempt.seconds)
        fb = self.fallback.solve(problem, accept=accept, retry=retry)
        return dataclasses.replace(fb, attempts=(att,) + tuple(fb.attempts))


def compile_psatz(f, eq=(), ineq=(), degree=None, multiplier=Multiplier.FIXED, form=GramForm.IMAGE,
                  gens=None) -> CompiledPsatz:
    """Compile the structure of (f, eq, ineq) at ``degree`` (see :class:`CompiledPsatz`)."""
    return CompiledPsatz(f, eq, ineq, degree, multiplier, form, gens)


def _union(a: Polynomial, b: Polynomial) -> Polynomial:
    terms = {e: 1.0 for e in a.terms}
    terms.update({e: 1.0 for e in b.terms})
    return Polynomial(a.gens, terms)


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

    @staticmethod
    def structure_key(f, eq, ineq, degree, multiplier, form, gens) -> tuple:
        mult = multiplier.value if isinstance(multiplier, Multiplier) else (
            ("q", tuple(sorted(multiplier.terms.items()))) if isinstance(multiplier, Polynomial) else float(multiplier))
        sup = tuple(_support(p.with_gens(gens)).tobytes() for p in (f,) + tuple(eq) + tuple(ineq))
        return (tuple(gens), int(degree), mult, GramForm(form).value, len(eq), len(ineq), sup)

    def get(self, f, eq=(), ineq=(), degree=None, multiplier=Multiplier.FIXED, form=GramForm.IMAGE, gens=None,
            key=None) -> CompiledPsatz:
        """A compiled structure that contains this instance (compiled on a miss).

        With ``key`` given (any hashable describing the structure), an instance whose
        supports fall outside the cached entry's is compiled on the union of both."""
        eq, ineq = tuple(eq), tuple(ineq)
        gens = tuple(gens) if gens is not None else common_gens(f, *eq, *ineq)
        if degree is None:
            degree = max(delta_min(f.with_gens(gens), [g.with_gens(gens) for g in eq],
                                   [h.with_gens(gens) for h in ineq]), 2)
        k = ("user", key, tuple(gens), int(degree), GramForm(form).value) if key is not None else \
            self.structure_key(f, eq, ineq, degree, multiplier, form, gens)
        comp = self._store.get(k)
        if comp is not None:
            if key is None or comp.contains(f, eq, ineq):
                self._store.move_to_end(k)
                return comp
            tmpl = comp._template_polys
            f_t = _union(tmpl[0], f.with_gens(gens))
            eq_t = tuple(_union(a, b.with_gens(gens)) for a, b in zip(tmpl[1:1 + len(eq)], eq))
            ineq_t = tuple(_union(a, b.with_gens(gens)) for a, b in zip(tmpl[1 + len(eq):], ineq))
        else:
            f_t, eq_t, ineq_t = f, eq, ineq
        comp = CompiledPsatz(f_t, eq_t, ineq_t, degree, multiplier, form, gens)
        self.compiles += 1
        self._store[k] = comp
        self._store.move_to_end(k)
        while len(self._store) > self.maxsize:
            self._store.popitem(last=False)
        return comp


#: the process-wide cache used by :func:`sospoly.compiled_psatz`-style callers (e.g. tritools).
DEFAULT_CACHE = PsatzCache()
