"""Compiled certificate structures of triangulation problems, and the one key that names them.

A triangulation only fills numbers into the Positivstellensatz structure of its kind (sospoly's
:class:`~sospoly.lowering.compiled.CompiledPsatz`): :data:`STRUCTURE_CACHE` keeps them, keyed by
:func:`structure_key` (number of views, region kinds, method, degree, formulation, Gram form).
:func:`corollary1_point_structure` is the structure of N point regions, Corollary 1, delta = 2 on the
full epipolar supports, with the theta slot of every fundamental-matrix entry read from its public
:class:`~sospoly.DataSlots` (the batched SDP fills theta directly from stacks of F_ij).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

import sospoly
from sospoly import GramForm, Multiplier, Polynomial, variables
from sospoly.budget import check_deadline

from ..model.constraints import Method
from ..model.stacked import view_pairs

__all__ = ["STRUCTURE_CACHE", "structure_key", "PointStructure", "corollary1_point_structure", "point_gens"]

#: compiled Positivstellensatz structures by :func:`structure_key` (least recently used dropped beyond 128).
STRUCTURE_CACHE = sospoly.PsatzCache(maxsize=128)


def structure_key(n_views: int, region_kinds, method, delta: int, formulation: str, form) -> tuple:
    """The cache key of a triangulation's certificate structure."""
    return (int(n_views), tuple(region_kinds), Method(method).value, int(delta), str(formulation),
            GramForm(form).value)


def point_gens(N: int) -> tuple:
    """The variables of an N-view point problem, as :func:`tritools.model.problem.build_problem` names them."""
    return variables([f"x{i + 1}_{k + 1}" for i in range(N) for k in range(2)])[0].gens


@dataclass(frozen=True)
class PointStructure:
    """The compiled Corollary 1, delta = 2 structure of N point regions and where its data go:
    ``f_slots`` (2N,) the theta positions of the x_k^2 terms of f, ``F_slots`` (K, 3, 3) the position of
    F_ij[a, b] (which multiplies x~_ia x~_jb) for the K view pairs of :func:`tritools.model.stacked.view_pairs`."""
    compiled: sospoly.CompiledPsatz
    f_slots: np.ndarray
    F_slots: np.ndarray

    def thetas(self, F: np.ndarray) -> np.ndarray:
        """theta (M, n_theta) of M problems from their unit-norm F_ij (M, K, 3, 3); f = sum_k x_k^2."""
        th = np.zeros((F.shape[0], self.compiled.n_theta))
        th[:, self.f_slots] = 1.0
        th[:, self.F_slots.reshape(-1)] = F.reshape(F.shape[0], -1)
        return th


@lru_cache(maxsize=32)
def corollary1_point_structure(N: int) -> PointStructure:
    gens = point_gens(N)
    n = 2 * N
    I, J = view_pairs(N)

    def mono(*ks):
        e = np.zeros(n, np.int64)
        for k in ks:
            e[k] += 1
        return e

    check_deadline("building the batched Corollary 1 structure")
    # exponent rows as Python ints (Polynomial's fast path: numpy integers are converted one by one, ~1 s at
    # 400 views for f alone)
    f = Polynomial(gens, {tuple(mono(k, k).tolist()): 1.0 for k in range(n)})
    exps = np.zeros((len(I), 3, 3, n), np.int64)
    eq = []
    for k, (i, j) in enumerate(zip(I, J)):
        if k % 8 == 0:                      # N(N - 1)/2 pairs: a long build at large N stops at the active deadline
            check_deadline("building the batched Corollary 1 structure")
        for a in range(3):
            for b in range(3):
                exps[k, a, b] = mono(*(([2 * i + a] if a < 2 else []) + ([2 * j + b] if b < 2 else [])))
        eq.append(Polynomial(gens, {tuple(e): 1.0 for e in exps[k].reshape(9, n).tolist()}))
    key = structure_key(N, ("point",) * N, Method.COROLLARY1, 2, "dense", GramForm.IMAGE)
    comp, _ = STRUCTURE_CACHE.get(f, eq, (), 2, Multiplier.FIXED, GramForm.IMAGE, gens=gens, key=key)
    slots = comp.slots
    f_slots = slots.index(0, np.array([mono(k, k) for k in range(n)]))
    F_slots = np.stack([slots.index(1 + k, exps[k].reshape(9, n)).reshape(3, 3) for k in range(len(I))]) \
        if len(I) else np.zeros((0, 3, 3), np.int64)
    if np.any(f_slots < 0) or np.any(F_slots < 0):          # pragma: no cover - the supports are complete
        raise AssertionError("the point structure does not hold every epipolar term")
    return PointStructure(comp, f_slots, F_slots)
