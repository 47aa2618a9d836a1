"""Refusing a fixed multiplier q that is evidently not SOS (review 26a F3).

The Positivstellensatz argument needs q >= 0 everywhere (and q > 0 where the bound is to hold): with
q = -(1 + x^2) the exact identity 5 + 6x^2 + x^4 = q (-x^2 - 5) "proves" -x^2 >= 5.  Deciding that q is SOS
needs a solver (:func:`sospoly.minimize` runs :func:`sospoly.is_sos`); this pure-data check refuses the evident
cases: a q of odd degree (not bounded below, so not SOS), a q negative at a point, or a top-degree form negative
at a point (then q -> -inf along that direction).  The points: the origin, +-e_i, and a fixed pseudo-random set at
the scales 1e-3, 1, 1e3 (the sign is read with a rounding allowance of 1e-12 of the terms' sizes).  A q that
vanishes somewhere, e.g. (y - 1)^2, is SOS and passes: the proofs refuse it instead, as they prove q >= q_min > 0
for every v (:func:`sospoly.analysis.proof.q_lower_bound`).
"""
from __future__ import annotations

import numpy as np

__all__ = ["check_q_not_evidently_negative"]

#: the relative rounding allowance of the sign test
_ROUNDING = 1e-12


def _points(n: int) -> np.ndarray:
    rng = np.random.default_rng(20261205)
    base = rng.standard_normal((32, n))
    eye = np.eye(n)
    pts = [np.zeros((1, n)), eye, -eye] + [s * base for s in (1e-3, 1.0, 1e3)]
    return np.vstack(pts)


def _values(E: np.ndarray, c: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(q at every point, sum of |terms|) for the terms (E, c)."""
    with np.errstate(over="ignore", invalid="ignore"):
        mono = np.prod(P[:, None, :] ** E[None, :, :], axis=2)
    return mono @ c, np.abs(mono) @ np.abs(c)


def check_q_not_evidently_negative(q) -> None:
    """ValueError naming why when ``q`` (a Polynomial) is evidently not SOS (module docstring)."""
    E, c = q.exponents(), q.coefficients()
    if not np.all(np.isfinite(c)):
        raise ValueError("the multiplier q has non-finite coefficients")
    if q.degree % 2:
        raise ValueError(f"the multiplier q has odd degree {q.degree}: it is not SOS (not bounded below)")
    n = E.shape[1]
    P = _points(n)
    for what, keep in (("q", np.ones(E.shape[0], bool)), ("the top-degree form of q", E.sum(axis=1) == q.degree)):
        val, size = _values(E[keep], c[keep], P)
        bad = np.isfinite(val) & (val < -_ROUNDING * size)
        if np.any(bad):
            i = int(np.argmax(bad))
            raise ValueError(f"the multiplier q is not SOS: {what} is {float(val[i]):.3g} < 0 at v = "
                             f"{tuple(float(t) for t in P[i])} (a Positivstellensatz certificate needs q >= 0)")
