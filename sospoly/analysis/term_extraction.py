"""Minimiser candidates from the moment matrices of a term-sparsity certificate.

Term-sparsity blocks follow the problem's sign symmetries: a block need not hold 1 and every x_i, and
when f is invariant under x -> D x (D a diagonal sign matrix) the first moments L(x_i) of the symmetric
measure vanish, so reading a point from first moments fails (TSSOS reads it from the block of 1 the
same way).  The second moments survive: every block holding 1 and x_i^2 (the block of 1 holds the
squares of the basis' degree-1 monomials: 1 + x_i^2 = 2 x_i) gives L(x_i^2), and the cross moments
L(x_i x_j) give relative signs.  For a measure supported on one orbit {D x*} of the symmetry group,
|x*_i| = sqrt(L(x_i^2) / L(1)) and sign(x*_i x*_j) = sign L(x_i x_j).

:func:`second_moment_candidates` returns the points with these magnitudes and every sign pattern the
moments leave open (fixed by L(x_i) when it is significant, then propagated along significant
L(x_i x_j); at most ``2 ** max_free`` patterns).  They are only candidates: the caller polishes them
and keeps the feasible ones (:func:`sospoly.minimize`).
"""
from __future__ import annotations

from itertools import product

import numpy as np

__all__ = ["collect_moments", "second_moment_candidates"]


def collect_moments(blocks) -> dict:
    """exponent tuple -> mean of the entries M[a, b] with b_a + b_b = exponent over all (basis, M) blocks."""
    acc = {}
    for B, M in blocks:
        if M is None or not np.all(np.isfinite(M)):
            continue
        for a in range(B.shape[0]):
            for b in range(a, B.shape[0]):
                key = tuple(int(t) for t in B[a] + B[b])
                acc.setdefault(key, []).append(float(M[a, b]))
    return {k: float(np.mean(v)) for k, v in acc.items()}


def second_moment_candidates(blocks, n: int, rel: float = 1e-3, max_free: int = 6) -> list:
    """Candidate points from second moments (module docstring); [] when L(1) or some L(x_i^2) is missing."""
    mom = collect_moments(blocks)
    one = mom.get((0,) * n)
    if one is None or one <= 0:
        return []
    unit = np.eye(n, dtype=np.int64)
    sq = [mom.get(tuple(2 * unit[i])) for i in range(n)]
    if any(v is None for v in sq):
        return []
    mag = np.sqrt(np.maximum(np.array(sq) / one, 0.0))
    sign = np.zeros(n)
    for i in range(n):
        m1 = mom.get(tuple(unit[i]))
        if m1 is not None and abs(m1 / one) > rel * max(mag[i], 1e-12):
            sign[i] = np.sign(m1)
    free = []
    for i in range(n):
        if sign[i] != 0 or mag[i] <= 1e-9:
            continue
        free.append(i)
        sign[i] = 1.0
        _propagate(i, sign, mag, mom, one, unit, rel)
    free = free[:max_free]
    out = []
    for pattern in product((1.0, -1.0), repeat=len(free)):
        s = sign.copy()
        for i, p in zip(free, pattern):
            s[i] = p
            _propagate(i, s, mag, mom, one, unit, rel, overwrite=True)
        out.append(np.where(s == 0, 1.0, s) * mag)
    return out


def _propagate(i, sign, mag, mom, one, unit, rel, overwrite=False):
    """Give every undetermined j with a significant L(x_i x_j) the sign sign_i * sign L(x_i x_j)."""
    stack = [i]
    seen = {i}
    while stack:
        a = stack.pop()
        for j in range(sign.size):
            if j in seen or (sign[j] != 0 and not overwrite) or mag[j] <= 1e-9:
                continue
            m2 = mom.get(tuple(unit[a] + unit[j]))
            if m2 is not None and abs(m2 / one) > rel * mag[a] * mag[j]:
                sign[j] = sign[a] * np.sign(m2)
                seen.add(j)
                stack.append(j)
