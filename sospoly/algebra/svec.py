"""The one place where the symmetric-matrix vectorisation (svec) lives.

Convention (Clarabel's ``PSDTriangleConeT``, and SCS's up to ordering): the upper
triangle of a symmetric ``s x s`` matrix X is stacked **column by column**,
off-diagonal entries multiplied by sqrt(2)::

    svec(X) = [X11, sqrt2 X12, X22, sqrt2 X13, sqrt2 X23, X33, ...]

so that ``<X, Y> = svec(X) . svec(Y)``.  The pair list ``(i, j), i <= j`` in that
order is :func:`triu_pairs`; :class:`sospoly.algebra.basis.GramBasis` uses the same order.
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

__all__ = ["SQRT2", "triu_pairs", "svec_scale", "svec", "smat", "svec_length"]

SQRT2 = math.sqrt(2.0)


def svec_length(s: int) -> int:
    return s * (s + 1) // 2


@lru_cache(maxsize=512)
def triu_pairs(s: int) -> tuple[np.ndarray, np.ndarray]:
    """Row and column indices (i <= j) of the upper triangle, column-wise."""
    i = np.concatenate([np.arange(j + 1) for j in range(s)]).astype(np.int64) if s else np.zeros(0, np.int64)
    j = np.concatenate([np.full(j + 1, j) for j in range(s)]).astype(np.int64) if s else np.zeros(0, np.int64)
    i.setflags(write=False)
    j.setflags(write=False)
    return i, j


@lru_cache(maxsize=512)
def svec_scale(s: int) -> np.ndarray:
    """Per-entry factor of svec: 1 on the diagonal, sqrt(2) off it."""
    i, j = triu_pairs(s)
    out = np.where(i == j, 1.0, SQRT2)
    out.setflags(write=False)
    return out


def svec(X: np.ndarray) -> np.ndarray:
    """svec of a symmetric matrix, or of a stack (..., s, s) along the last two axes (the symmetric part
    0.5 (X + X^T) is taken, so round-off asymmetry does not bias the result)."""
    X = np.asarray(X, dtype=float)
    s = X.shape[-1]
    i, j = triu_pairs(s)
    return 0.5 * (X[..., i, j] + X[..., j, i]) * svec_scale(s)


def smat(v: np.ndarray, s: int | None = None) -> np.ndarray:
    """The symmetric matrix of an svec, or of a stack (..., L) along the last axis (``s``: the side,
    derived from L when omitted)."""
    v = np.asarray(v, dtype=float)
    L = v.shape[-1]
    if s is None:
        s = int(round((math.sqrt(8 * L + 1) - 1) / 2))
    if svec_length(s) != L:
        raise ValueError(f"vector of length {L} is not an svec")
    i, j = triu_pairs(s)
    X = np.zeros(v.shape[:-1] + (s, s))
    vals = v / svec_scale(s)
    X[..., i, j] = vals
    X[..., j, i] = vals
    return X
