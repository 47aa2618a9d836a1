"""A proven lower bound of a solved sum-of-ratios program (:func:`sospoly.minimize_ratios`).

The program (Bugarin, Henrion & Lasserre) certifies, for k = 0..m-1,

    a_k (p_k - w_k q_k) - sum_j r_kj g_j - sum_j s_kj h_j  =  b_k^T G_k b_k          (SOS, Gram G_k)

with w_0 = lambda - w_1 - ... - w_{m-1}, r_kj free, s_kj SOS (Gram S_kj), a_k > 0 a power of two (each certificate
at its own ratio's scale).  The solver's values satisfy it only
up to two defects, both accounted for here, as :mod:`sospoly.analysis.rigor` does for one Positivstellensatz
certificate:

* the **identity residual** e_k = U_k - b_k^T G_k b_k, with U_k the left-hand side recomputed from the decision
  values and the data **in exact rational arithmetic** (every float is a dyadic rational), so sum_k w_k = lambda
  holds exactly and e_k is the whole error;
* the **PSD defects** eps_k = max(0, -lambda_min(G_k)) and eta_kj of S_kj (plus the eigenvalue computation's error
  bound): b^T G b >= -eps ||b||^2.

On the feasible set K (g = 0, h >= 0) inside a box |v_i| <= r_i that holds K (:func:`sospoly.analysis.proof.
constraint_box`), a_k (p_k - w_k q_k) >= -D_k with D_k = eps_k W_k + E_k + sum_j eta_kj W_kj H_j (W: bounds of
||b(v)||^2, E_k >= |e_k(v)|, H_j >= |h_j(v)| on the box), and q_k >= q_min,k > 0 on K (the denominators' proven
bounds), so

    sum_k p_k / q_k  >=  sum_k w_k - sum_k D_k / (a_k q_min,k)  =  lambda - sum_k D_k / (a_k q_min,k)       on K.

Every float evaluation of the margin is rounded up.  Without a box (K not bounded by its constraints) nothing is
proven: the caller reports no bound (review 25b: the solver's lambda, reported as it was, stood 8.7e-8 above the
exact minimum of a rescaled problem, "optimal").
"""
from __future__ import annotations

from fractions import Fraction

import numpy as np

from .analysis.proof import constraint_box
from .analysis.rigor import block_weight, poly_sup, psd_defect_of

__all__ = ["proven_ratio_bound", "MARGIN_ROUND_UP"]

#: the float evaluation of the margin (sums of at most ~1e6 non-negative terms) is multiplied by this
MARGIN_ROUND_UP = 1.0 + 1e-9


def _exact(p) -> dict:
    """{exponent tuple: Fraction} of a Polynomial (its float coefficients, exactly)."""
    return {e: Fraction(float(c)) for e, c in p.terms.items() if c != 0}


def _add(acc: dict, p: dict, sign: int = 1) -> None:
    for e, c in p.items():
        acc[e] = acc.get(e, 0) + sign * c


def _mul(a: dict, b: dict) -> dict:
    out: dict = {}
    for ea, ca in a.items():
        for eb, cb in b.items():
            e = tuple(i + j for i, j in zip(ea, eb))
            out[e] = out.get(e, 0) + ca * cb
    return out


def _free(prog, x: np.ndarray, name: str) -> dict:
    """The free polynomial of block ``name`` at the decision values x, exactly."""
    blk = prog.block(name)
    return {tuple(int(v) for v in e): Fraction(float(c)) for e, c in zip(blk.monomials, x[blk.slice]) if c != 0}


def _gram_poly(G: np.ndarray, b: np.ndarray) -> dict:
    """b^T G b exactly, for the float matrix G (symmetric: G_ij and G_ji both counted as stored)."""
    out: dict = {}
    rows = [tuple(int(v) for v in r) for r in b]
    for i, ei in enumerate(rows):
        for j, ej in enumerate(rows):
            g = float(G[i, j])
            if g != 0.0:
                e = tuple(a + c for a, c in zip(ei, ej))
                out[e] = out.get(e, 0) + Fraction(g)
    return out


def _sup(poly: dict, r: np.ndarray) -> float:
    """An upper bound of |poly(v)| on the box |v_i| <= r_i (the exact coefficients' magnitudes, rounded up)."""
    if not poly:
        return 0.0
    E = np.array(list(poly.keys()), dtype=float)
    c = np.array([abs(float(v)) for v in poly.values()])
    with np.errstate(over="ignore"):
        mono = np.prod(r[None, :] ** E, axis=1)
        return float(np.sum(c * mono)) * MARGIN_ROUND_UP * (1.0 + 4.0 * np.finfo(float).eps)


def proven_ratio_bound(prog, names: list, sol, pairs, eq, ineq, q_min, weights=None) -> tuple[float, str]:
    """(a proven lower bound of min sum p_k / q_k on K for the program ``prog`` of :func:`sospoly.ratios._build`
    solved as ``sol`` -- the normalised data ``pairs``, ``eq``, ``ineq`` exactly as the program holds them -- or
    -inf; a note): the module docstring's bound, with ``q_min`` (m,) proven lower bounds of the q_k on K and
    ``weights`` the certificates' factors a_k (powers of two; None: all 1)."""
    n = len(prog.gens)
    r = constraint_box(eq, ineq, n)
    if r is None:
        return -np.inf, "the constraints imply no box around the set, so the certificate's defects cannot be bounded"
    if not all(float(q) > 0 for q in q_min):
        return -np.inf, "a denominator is not proven positive"
    x = np.asarray(sol.x, float)
    lam_blk = prog.block("lambda")
    lam = float(x[lam_blk.slice][0])
    m = len(pairs)
    ws = [_free(prog, x, f"w{k}") for k in range(1, m)]
    w0 = {(0,) * n: Fraction(lam)}
    for w in ws:
        _add(w0, w, -1)
    data_eq, data_ineq = [_exact(g) for g in eq], [_exact(h) for h in ineq]
    h_sup = [poly_sup(h, r) * MARGIN_ROUND_UP for h in ineq]
    margin = 0.0
    weights = [1.0] * m if weights is None else [float(a) for a in weights]
    if not all(a > 0 and np.isfinite(a) for a in weights):
        return -np.inf, "a certificate's weight is not a positive number"
    for k, (p, q) in enumerate(pairs):
        a = Fraction(weights[k])
        U = {e: a * c for e, c in _exact(p).items()}
        _add(U, {e: a * c for e, c in _mul(w0 if k == 0 else ws[k - 1], _exact(q)).items()}, -1)
        for j, g in enumerate(data_eq):
            _add(U, _mul(_free(prog, x, f"r{k}_{j}"), g), -1)
        defect = 0.0
        for j, h in enumerate(data_ineq):
            blk = prog.block(f"s{k}_{j}")
            S = _gram_matrix(blk, x)
            _add(U, _mul(_gram_poly(S, blk.gram.b), h), -1)
            defect += psd_defect_of(S) * block_weight(blk.gram.b, r, False) * h_sup[j]
        con = prog.sos_constraints[[c.name for c in prog.sos_constraints].index(names[k])]
        G, b = sol.grams.get(names[k]), con.gram.blocks[0].b
        if G is None or len(con.gram.blocks) != 1 or not np.all(np.isfinite(G)):
            return -np.inf, f"certificate {names[k]} has no finite Gram matrix"
        _add(U, _gram_poly(G, b), -1)                       # U is now e_k, exactly
        D = psd_defect_of(G) * block_weight(b, r, False) + _sup(U, r) + defect
        margin += D * MARGIN_ROUND_UP / (weights[k] * float(q_min[k]))
    if not np.isfinite(margin):
        return -np.inf, "the certificate's margin on the constraints' box is not finite"
    lower = float(np.nextafter(lam - margin * MARGIN_ROUND_UP, -np.inf))
    return lower, f"proven on the constraints' box (margin {margin:.3g} in normalised units)"


def _gram_matrix(blk, x: np.ndarray) -> np.ndarray:
    """The symmetric Gram matrix of an SOS-polynomial block at the decision values x."""
    s = blk.gram.size
    S = np.zeros((s, s))
    S[blk.gram.pair_i, blk.gram.pair_j] = x[blk.slice]
    S[blk.gram.pair_j, blk.gram.pair_i] = x[blk.slice]
    return S
