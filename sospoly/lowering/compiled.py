"""Compile once, solve many: a Positivstellensatz *structure* lowered once.

A :class:`~sospoly.certificates.psatz.PsatzStructure` is an SOS program whose data -- the
coefficient vector theta of :class:`~sospoly.certificates.psatz.DataSlots`, and for a free
multiplier the level c -- enter as parameters.  Its conic data (A, b) of
:func:`sospoly.lowering.conic.lower` are therefore *affine* in them:

    A = A_0 + sum_t theta_t A_t + c A_c,      b = b_0 + sum_t theta_t b_t + c b_c.

:class:`LoweredPsatz` lowers the structure once and stores the maps theta -> A.data (on the
fixed sparsity pattern of A) and theta -> b as sparse matrices.  A new instance then costs one
coefficient look-up and two sparse mat-vecs (:meth:`LoweredPsatz.problem_from_theta`), and a
batch of instances one sparse mat-mat (:meth:`LoweredPsatz.dense_batch`).

Parameters of the structure (see :mod:`sospoly.certificates.psatz`): ``f:t`` feeds theta entry t
of f; ``m:t`` is the t-th term *slot* of every constrained polynomial at once (the multipliers own
disjoint columns, so the slot's matrix splits by column block into the matrix of each polynomial's
t-th coefficient); ``c`` is the GEVP level of a free multiplier.

This module only lowers: solving a lowered structure (one instance, a batch with the batched
interior-point method, the vectorised bounds) is :class:`sospoly.CompiledPsatz` of
:mod:`sospoly.solvers.compiled_solve`, with :func:`sospoly.compile_psatz` and :class:`sospoly.PsatzCache`
(compiled structures keyed by the structure or by a caller's key).  A solver consumes a lowered problem;
nothing here imports :mod:`sospoly.solvers`.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..budget import as_budget, check_deadline
from ..certificates.psatz import (DataSlots, Multiplier, PsatzProblem, PsatzStructure, StructureMismatch, as_multiplier,
                                  certificate_shape, check_size, checked_inputs, fixed_q_for, psatz_structure)
from .conic import ConicProblem, GramForm, lower

__all__ = ["LoweredPsatz", "CompiledInstance", "structure_for", "StructureMismatch"]


@dataclass(frozen=True, eq=False)
class CompiledInstance:
    """One instance's numbers in a compiled structure: theta and its conic problem
    (:func:`sospoly.solve_psatz` accepts it like a :class:`~sospoly.certificates.psatz.PsatzProblem`)."""
    compiled: LoweredPsatz
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


def _param_source(name: str, col_owner: np.ndarray, cols: np.ndarray, offsets: np.ndarray, n_theta: int):
    """theta index (n_theta for the GEVP level c) of each entry of a parameter's matrix."""
    if name == "c":
        return np.full(cols.size, n_theta, np.int64)
    kind, t = name.split(":")
    t = int(t)
    if kind == "f":
        return np.full(cols.size, offsets[0] + t, np.int64)
    return offsets[col_owner[cols]] + t        # "m:t": the column's owner polynomial


class LoweredPsatz:
    """A Positivstellensatz structure lowered once (see module docstring); the solvers of its instances are
    those of its subclass :class:`sospoly.CompiledPsatz` (:mod:`sospoly.solvers.compiled_solve`)."""

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

def structure_for(f, eq=(), ineq=(), degree=None, multiplier=Multiplier.FIXED, gens=None, *, sparsity="none",
                  low_degree=None, slots: DataSlots | None = None, budget=None, form=None) -> PsatzStructure:
    """The structure :func:`sospoly.build_psatz` builds for these polynomials (on ``slots`` when given,
    e.g. the union of several instances' supports), checked against ``budget`` the same way; ``form``: the Gram
    form it will be lowered in (the image form is sized on its Gram blocks' aggregate sparsity where the dense
    estimate does not fit: :mod:`sospoly.certificates.sizing`)."""
    budget = as_budget(budget)
    f, eq, ineq, gens, degree = checked_inputs(f, eq, ineq, degree, gens, budget.max_gram_side)
    multiplier = as_multiplier(multiplier)
    shape = certificate_shape(sparsity, gens, degree, f, eq, ineq, low_degree=low_degree,
                              max_gram_side=budget.max_gram_side)
    q = fixed_q_for(multiplier, gens, degree, f, shape.is_dense)
    slots = slots if slots is not None else DataSlots.of(f, eq, ineq, gens)
    check_size(shape, budget, q is None, len(gens), degree, f.degree, slots=slots, q=q,
               image_form=form is not None and GramForm(form) == GramForm.IMAGE)
    return psatz_structure(slots, degree, shape, q)


