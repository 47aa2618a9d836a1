"""Rigorous outer bounds from dual multipliers (docs/uncertainty.md, "Rigour").

Every dual point of a bound problem gives, through :func:`tritools.uncertain.sets.view_coefficients`,
coefficients ``gamma_i`` with ``sum_i gamma_i . r_i X~ >= 0`` for every X of S (the ``r_i`` the exact
signed camera rows).  With ``xi = X - X0`` this is ``a' xi + b >= 0``, and the floats ``a^, b^``
computed here satisfy ``|a - a^| <= ae``, ``|b - b^| <= be`` componentwise (standard bounds
``(n + 4) eps sum |terms|`` for sums of products, generous by a factor of two).

For a target linear function ``q' xi`` and ``lambda = a^.q / q.q > 0``::

    q' xi = (a' xi) / lambda + (q - a / lambda)' xi >= -(b^ + be) / lambda - rho M,
    rho   = sum_j |q_j - a^_j / lambda| + ae_j / lambda,      M = sup_S ||xi||_inf,

so ``q' xi >= beta - rho M`` (:func:`lower_bounds`).  ``M`` is finite and bounded a posteriori from
the six coordinate bounds themselves (:func:`box_from_bounds`): ``|xi_k| <= V + rho_max M`` gives
``M <= V / (1 - rho_max)`` when ``rho_max < 1`` -- and the same six inequalities applied to a
recession direction ``d`` of S give ``||d||_inf <= rho_max ||d||_inf``, so S is bounded: the box
needs no a-priori bound.  All final roundings are outwards.
"""
from __future__ import annotations

import numpy as np

from .sets import EPS

__all__ = ["combine", "lower_bounds", "box_from_bounds", "round_down", "round_up"]


def round_down(x: np.ndarray) -> np.ndarray:
    return np.nextafter(np.nextafter(x, -np.inf), -np.inf)


def round_up(x: np.ndarray) -> np.ndarray:
    return np.nextafter(np.nextafter(x, np.inf), np.inf)


def combine(gamma: np.ndarray, gerr: np.ndarray, R: np.ndarray, X0: np.ndarray):
    """``w = sum_i gamma_i r_i`` (gamma (K, N, 3), R (K, N, 3, 4)) shifted to ``xi = X - X0`` (K, 3):
    returns float ``a^ (K, 3), ae (K, 3), b^ (K,), be (K,)``.  Computed in gamma's precision (long
    double from the caller: georeferenced worlds cancel here), rounded to float with the
    conversion added to the error bounds."""
    E = float(np.finfo(gamma.dtype).eps)
    R = R.astype(gamma.dtype)
    X0 = X0.astype(gamma.dtype)
    terms = gamma[..., None] * R                                    # (K, N, 3, 4)
    n = 3 * R.shape[1]
    w = terms.sum(axis=(1, 2))
    we = (n + 4) * E * np.abs(terms).sum(axis=(1, 2)) + np.einsum("kni,knij->kj", gerr, np.abs(R))
    we = we * (1 + 4 * E)
    a, ae = w[:, :3], we[:, :3]
    t = a * X0
    b = t.sum(axis=1) + w[:, 3]
    be = 8 * E * (np.abs(t).sum(axis=1) + np.abs(w[:, 3])) + np.einsum("kj,kj->k", ae, np.abs(X0)) + we[:, 3]
    af, bf = a.astype(float), b.astype(float)
    ae = (ae + np.abs(a - af.astype(gamma.dtype))).astype(float) * (1 + 4 * EPS) + EPS * np.abs(af) * 1e-3
    be = (be + np.abs(b - bf.astype(gamma.dtype))).astype(float) * (1 + 4 * EPS)
    return af, round_up(ae), bf, round_up(be)


def lower_bounds(a, ae, b, be, q):
    """``(beta, rho, ok)`` with ``q' xi >= beta - rho M`` on S for each row (module docstring);
    ``ok`` False where the multiplier does not point along ``q`` (no bound)."""
    lam = np.einsum("kj,kj->k", a, q) / np.einsum("kj,kj->k", q, q)
    ok = np.isfinite(lam) & (lam > 0) & np.all(np.isfinite(a), axis=1) & np.isfinite(b)
    lam = np.where(ok, lam, 1.0)
    with np.errstate(over="ignore", invalid="ignore"):
        beta = round_down(-(b + be) / lam)
        beta = beta - 4 * EPS * np.abs(beta)
        rho = (np.abs(q - a / lam[:, None]) + ae / lam[:, None]).sum(axis=1)
        rho = rho * (1 + 16 * EPS) + 16 * EPS * (np.abs(a) / lam[:, None]).sum(axis=1)
    ok &= np.isfinite(beta) & np.isfinite(rho)
    return beta, rho, ok


def box_from_bounds(beta_lo, rho_lo, beta_hi, rho_hi):
    """Certified box of ``xi`` from ``xi_k >= beta_lo_k - rho_lo_k M`` and ``-xi_k >= beta_hi_k - rho_hi_k M``
    (arrays (K, 3)): ``(lo, hi, M)``, inf where ``rho_max >= 1`` (no certificate)."""
    V = np.maximum(np.abs(beta_lo), np.abs(beta_hi)).max(axis=1)
    rho = np.maximum(rho_lo, rho_hi).max(axis=1)
    good = rho < 0.5
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        M = np.where(good, round_up(V / np.where(good, 1.0 - rho, 1.0)) * (1 + 8 * EPS), np.inf)
        lo = round_down(beta_lo - rho_lo * M[:, None] * (1 + 4 * EPS))
        hi = round_up(-beta_hi + rho_hi * M[:, None] * (1 + 4 * EPS))
    lo = np.where(good[:, None], lo, -np.inf)
    hi = np.where(good[:, None], hi, np.inf)
    return lo, hi, M
