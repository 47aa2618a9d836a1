"""Lower bounds that hold without a user's radius (the default of :func:`sospoly.minimize`).

A solver's certificate u = q (f - c) + sum r_k g_k - sum s_k h_k = sum_j b_j^T G_j b_j holds only up to
the PSD defect of the G_j (and of the s_k) and the residual e of the coefficient identity.  Two arguments
turn it into a bound valid in floating point:

1. **A box from the constraints** (:func:`constraint_box`): a quadratic constraint whose Hessian is
   definite on its variables S (h >= 0 with -Hess h > 0, or g = 0 with either sign) confines v_S to a ball
   -- centre v0 = -A^-1 b / 2, radius^2 = (v0^T A v0 - c0) / lambda_min(A) for the set v^T A v + b^T v + c0
   <= 0 -- and a linear constraint in one variable to a half-line.  When every variable is bounded, the
   feasible set (so every minimiser) lies in the box, and :func:`sospoly.analysis.rigor.rigorous_psatz_bound`
   subtracts the defects' worst case on it.

2. **The shifted certificate** (:func:`global_psatz_bound`, valid for every v, no box): at the level
   c' = c - m (m a small margin) the target is u' = u + m q.  Each s_k is made PSD by adding its defect
   eta_k I (u' changes by -eta_k ||b_sk||^2 h_k, computed); each G_j is shifted by t I and projected onto
   the exact identities (each monomial's residual spread evenly over its Gram entries -- Peyrl & Parrilo's
   projection, in floating point).  The residual e2 left by rounding is bounded and absorbed, monomial by
   monomial, into the diagonal: for v^m = b_i b_j, |e2_m v^m| <= |e2_m| (b_i^2 + b_j^2) / 2, so
   u' >= sum_j b_j^T (G2_j - D_j) b_j, and u' >= 0 everywhere once every lambda_min(G2_j - D_j) minus its
   eigenvalue error bound is >= 0.  Then, on the feasible set, q (f - c') >= 0, and f >= c' where
   q > 0: :func:`q_lower_bound` proves q >= q_min > 0 for every v (a constant; q = 1 + terms that are even
   powers with positive coefficients, e.g. (1 + ||v||^2)^k; a free SOS q whose Gram basis holds 1:
   q >= lambda_min(Q); any other fixed q: its minimum proven by :func:`sospoly.minimize`,
   :mod:`sospoly.analysis.q_floor`).  A multiplier not proven positive proves nothing (q vanishing on the set
   makes every level "feasible": min x^3 s.t. y = 1 with q = (y - 1)^2).

The kernel directions b(v*) of the solver's G (the minimisers) gain m q(v*) > 0 from the lowered level,
which is what lets the projection stay PSD; the margin m and the shift t are tried small first.

3. **A box from a sublevel set of f** (:func:`sublevel_box`; used for unconstrained programs, where every
   point is feasible): a minimiser satisfies f(v*) <= U = f at any point; with a separable minorant
   f(v) >= C + sum_i P_i(v_i^2) (mixed terms by weighted AM-GM) whose P_i all grow, f(v) <= U confines every
   v_i to a bounded interval.  The box then serves as in item 1.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..algebra.polynomial import Polynomial
from .rigor import solution_at_level, gram_pairs, psd_defect_of, u_terms, certificate_residual

__all__ = ["GlobalBound", "global_psatz_bound", "constraint_box", "sublevel_box", "q_lower_bound", "unsolved_claim",
           "GLOBAL_MARGINS", "WEAK_MARGINS", "SHIFT_FRACTIONS"]

_EPS = np.finfo(float).eps
#: margins m tried by :func:`global_psatz_bound`, relative to max(scale, |c|), smallest first
GLOBAL_MARGINS = (1e-10, 1e-9, 1e-8, 1e-7)
#: larger margins tried when none of GLOBAL_MARGINS proves a bound: a weaker bound, still proven (e.g. an infimum
#: that is not attained, where the solver's level lies above it)
WEAK_MARGINS = (1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1)
#: shifts t tried per margin, relative to m
SHIFT_FRACTIONS = (1e-1, 1e-2, 1e-3, 0.0)
#: box radii inflated by this relative amount (the rounding of a small linear solve, generously)
BOX_SAFETY = 1e-6
#: a quadratic constraint's Hessian with a condition number above this gives no box
MAX_BOX_CONDITION = 1e8


@dataclass(frozen=True)
class GlobalBound:
    """f >= ``lower_bound`` on the feasible set (-inf when nothing was proven); ``margin`` m and ``shift`` t
    of the proof, ``q_min`` the proven lower bound of q, ``message`` why it failed."""
    lower_bound: float
    margin: float
    shift: float
    q_min: float
    message: str = ""


def q_lower_bound(structure, sol) -> float:
    """A lower bound of the multiplier q valid for *every* v (module docstring, item 2); 0 when none is proven."""
    if structure.free:
        Q = None if sol is None else sol.grams.get("q")
        b = structure.program.block("q").gram.b
        if Q is None or not np.any(np.all(b == 0, axis=1)):
            return 0.0
        lam = np.linalg.eigvalsh(0.5 * (Q + Q.T))
        return max(0.0, float(lam[0]) - 8 * Q.shape[0] * _EPS * float(np.abs(lam).max()))
    q = structure.q
    if not q.terms:
        return 0.0
    E, c = q.exponents(), q.coefficients()
    const = float(c[E.sum(axis=1) == 0].sum()) if E.size else 0.0
    rest = E.sum(axis=1) > 0
    if np.any(rest & ~(np.all(E % 2 == 0, axis=1) & (c > 0))) or not const > 0:
        from .q_floor import proven_floor          # any other q: its proven minimum (sospoly.minimize)

        return proven_floor(q)
    return const


def _product_index(gb, E: np.ndarray) -> np.ndarray:
    return np.asarray(gb.product_index.find(E, missing_ok=True), np.int64)


def _ineq_shift_terms(psatz, structure, sol, n_products, gb):
    """(coefficients (n_products,), rounding bounds, ok) of sum_k eta_k ||b_sk||^2 h_k, eta_k the PSD defect of
    s_k (module docstring, item 2)."""
    coef, rnd = np.zeros(n_products), np.zeros(n_products)
    prog = structure.program
    x = np.asarray(sol.x, float)
    ineq = getattr(psatz, "ineq", None)
    if structure.slots.n_ineq and ineq is None:
        return coef, rnd, False
    for k in range(structure.slots.n_ineq):
        blk = prog.block(f"s{k}")
        S = np.zeros((blk.gram.size, blk.gram.size))
        S[blk.gram.pair_i, blk.gram.pair_j] = x[blk.slice]
        S[blk.gram.pair_j, blk.gram.pair_i] = x[blk.slice]
        eta = psd_defect_of(S)
        if eta == 0.0:
            continue
        h = ineq[k]
        B = Polynomial(h.gens, {tuple(int(t) for t in 2 * e): 1.0 for e in blk.gram.b})
        P, A = B * h, B * Polynomial(h.gens, {e: abs(v) for e, v in h.terms.items()})
        if not P.terms:
            continue
        idx = _product_index(gb, P.exponents())
        if np.any(idx < 0):
            return coef, rnd, False
        np.add.at(coef, idx, eta * P.coefficients())
        ia = _product_index(gb, A.exponents())
        np.add.at(rnd, ia, 4 * (len(B.terms) + 4) * _EPS * eta * A.coefficients())
    return coef, rnd, True


def global_psatz_bound(psatz, sol, c: float, scale: float = 1.0, margins=GLOBAL_MARGINS,
                       shifts=SHIFT_FRACTIONS, deadline=None) -> GlobalBound:
    """The shifted-certificate bound of the module docstring (item 2): the largest c - m (m in ``margins`` times
    max(scale, |c|)) proven, or -inf.  ``deadline`` (a :class:`sospoly.budget.Deadline`): no further margin is
    tried once it has expired (each trial costs a residual of the whole certificate)."""
    structure = psatz.structure
    qmin = q_lower_bound(structure, sol)
    if not qmin > 0:
        return GlobalBound(-np.inf, np.inf, np.nan, qmin, "the multiplier q is not proven positive everywhere")
    theta = np.asarray(psatz.theta, float)
    u = structure.u
    gb = u.gram
    names = u.block_names()
    if any(name not in sol.grams for name in names):
        return GlobalBound(-np.inf, np.inf, np.nan, qmin, "missing Gram matrices")
    G = np.concatenate([gram_pairs(sol.grams[name], b.size) for name, b in zip(names, gb.blocks)])
    w = np.where(gb.pair_diag, 1.0, 2.0)
    pm = gb.pair_monomial
    npr = gb.n_products
    cnt = np.bincount(pm, minlength=npr).astype(float)
    s_coef, s_rnd, ok = _ineq_shift_terms(psatz, structure, sol, npr, gb)
    if not ok:
        return GlobalBound(-np.inf, np.inf, np.nan, qmin, "an inequality multiplier's shift has monomials outside u")
    why = "no shifted certificate is PSD"
    for rel in margins:
        if deadline is not None and deadline.expired:
            return GlobalBound(-np.inf, np.inf, np.nan, qmin, "time limit reached before the every-point proof")
        m = rel * max(float(scale), abs(float(c)), 1e-300)
        level = float(c) - m
        E, e, rnd = certificate_residual(structure, theta, sol, level)
        idx = _product_index(gb, E)
        stray = (idx < 0) & ((np.abs(e) + rnd) > 0)
        if np.any(stray):
            return GlobalBound(-np.inf, np.inf, np.nan, qmin, "the residual has monomials outside every Gram block")
        e_p, r_p = np.zeros(npr), np.zeros(npr)
        keep = idx >= 0
        np.add.at(e_p, idx[keep], e[keep])
        np.add.at(r_p, idx[keep], rnd[keep])
        e_p -= s_coef
        r_p += s_rnd + 4 * _EPS * np.abs(s_coef)
        zero = _structural_zeros(structure, theta, sol, level, gb, s_coef)
        alive = _facial_reduction(gb, zero)
        for frac in shifts:
            t = frac * m
            G2 = _projected(gb, G, alive, e_p, t, w)
            dG = G2 - G
            e2 = e_p - np.bincount(pm, weights=w * dG, minlength=npr)
            bound = np.abs(e2) + r_p + 8 * (cnt + 4) * _EPS * (
                np.abs(e_p) + np.bincount(pm, weights=w * (np.abs(G2) + np.abs(G) + np.abs(dG)), minlength=npr))
            live_mono = np.bincount(pm, weights=alive.astype(float), minlength=npr) > 0
            bound = np.where(zero & ~live_mono, 0.0, bound)     # exactly 0 = 0: no alive entry, no target
            if _absorbed_psd(gb, G2, bound, alive):
                return GlobalBound(level, m, t, qmin, "")
    return GlobalBound(-np.inf, np.inf, np.nan, qmin, why)


def _structural_zeros(structure, theta, sol, level, gb, s_coef) -> np.ndarray:
    """Products whose coefficient in u' is exactly 0 (every contribution an exact zero)."""
    E_u, v_u = u_terms(structure, theta, solution_at_level(structure, sol.x, level), level)
    idx = _product_index(gb, E_u)
    present = np.zeros(gb.n_products)
    ok = idx >= 0
    np.add.at(present, idx[ok], np.abs(v_u[ok]))
    return (present == 0) & (s_coef == 0)


def _facial_reduction(gb, zero: np.ndarray) -> np.ndarray:
    """Alive pairs (both rows alive) after removing the rows the identity forces to zero: a product with a zero
    target whose alive entries are all diagonal forces those diagonal entries, hence their rows, to 0."""
    live = [np.ones(b.size, bool) for b in gb.blocks]
    pi = np.concatenate([b.pair_i for b in gb.blocks])
    pj = np.concatenate([b.pair_j for b in gb.blocks])
    pb = gb.pair_block
    pm = gb.pair_monomial
    while True:
        alive = np.array([live[j][i] and live[j][k] for j, i, k in zip(pb, pi, pj)], bool)
        offdiag_alive = np.bincount(pm, weights=(alive & ~gb.pair_diag).astype(float), minlength=gb.n_products) > 0
        kill = alive & gb.pair_diag & zero[pm] & ~offdiag_alive[pm]
        if not kill.any():
            return alive
        for p in np.nonzero(kill)[0]:
            live[pb[p]][pi[p]] = False


def _projected(gb, G, alive, e_p, t, w):
    """G + t I on the alive pairs (0 on the others), plus each product's residual spread evenly over its alive
    entries (the orthogonal projection onto the exact identities)."""
    pm = gb.pair_monomial
    npr = gb.n_products
    G1 = np.where(alive, G + np.where(gb.pair_diag, t, 0.0), 0.0)
    target = e_p + np.bincount(pm, weights=w * G, minlength=npr)
    resid = target - np.bincount(pm, weights=w * G1, minlength=npr)
    W = np.bincount(pm, weights=w * alive, minlength=npr)
    return G1 + np.where(alive & (W[pm] > 0), resid[pm] / np.where(W[pm] > 0, W[pm], 1.0), 0.0)


def _absorbed_psd(gb, G2: np.ndarray, bound: np.ndarray, alive: np.ndarray) -> bool:
    """Is every block's G2 - D_j PSD on its alive rows, D the diagonal absorbing |e2_m| (b_i^2 + b_j^2) / 2
    (module docstring)?  False when a product with a non-zero bound has no alive entry."""
    pm = gb.pair_monomial
    first = np.full(gb.n_products, -1, np.int64)
    ids = np.nonzero(alive)[0]
    first[pm[ids[::-1]]] = ids[::-1]
    D = [np.zeros(b.size) for b in gb.blocks]
    for p_mono in np.nonzero(bound > 0)[0]:
        p = first[p_mono]
        if p < 0:
            return False
        j = int(gb.pair_block[p])
        blk = gb.blocks[j]
        loc = p - int(gb.block_offsets[j])
        D[j][int(blk.pair_i[loc])] += 0.5 * bound[p_mono]
        D[j][int(blk.pair_j[loc])] += 0.5 * bound[p_mono]
    for j, blk in enumerate(gb.blocks):
        off = int(gb.block_offsets[j])
        s = blk.size
        M = np.zeros((s, s))
        vals = G2[off:off + blk.n_pairs]
        M[blk.pair_i, blk.pair_j] = vals
        M[blk.pair_j, blk.pair_i] = vals
        rows = np.zeros(s, bool)
        a = alive[off:off + blk.n_pairs]
        rows[blk.pair_i[a]] = True
        if not rows.any():
            continue
        # G2 - diag(D) PSD (not lambda_min(G2) >= max D: a large D on one row -- the rounding of a constant term
        # of ~1e8 -- would then have to fit under the smallest eigenvalue of another direction, review 26a F1);
        # err bounds the eigenvalue computation and the rounding of the subtraction on the diagonal
        Mr = M[np.ix_(rows, rows)]
        d = D[j][rows]
        lam = np.linalg.eigvalsh(Mr - np.diag(d))
        err = 8 * s * _EPS * max(float(np.abs(lam).max()), 1e-300) + 2 * _EPS * float(np.max(np.abs(np.diag(Mr)) + d))
        if float(lam[0]) - err < 0.0:
            return False
    return True


# ----------------------------------------------------------------------------- a box from the constraints
def _quadratic_parts(p: Polynomial, S: np.ndarray):
    """(A, b, c0) with p = v_S^T A v_S + b^T v_S + c0 for a polynomial of degree <= 2 over the variables S."""
    pos = {int(v): i for i, v in enumerate(S)}
    k = len(S)
    A, b, c0 = np.zeros((k, k)), np.zeros(k), 0.0
    for e, c in p.terms.items():
        nz = [i for i, d in enumerate(e) if d]
        if not nz:
            c0 += c
        elif len(nz) == 1 and e[nz[0]] == 1:
            b[pos[nz[0]]] += c
        elif len(nz) == 1:
            A[pos[nz[0]], pos[nz[0]]] += c
        else:
            i, j = pos[nz[0]], pos[nz[1]]
            A[i, j] += 0.5 * c
            A[j, i] += 0.5 * c
    return A, b, c0


def _ball_of(A, b, c0) -> float | None:
    """A radius R >= ||v|| for every v with v^T A v + b^T v + c0 <= 0 (A positive definite, well conditioned)."""
    lam = np.linalg.eigvalsh(A)
    if not lam[0] > 0 or lam[-1] > MAX_BOX_CONDITION * lam[0]:
        return None
    v0 = -0.5 * np.linalg.solve(A, b)
    rho = float(v0 @ A @ v0 - c0)
    R = float(np.linalg.norm(v0)) + np.sqrt(max(rho, 0.0) / lam[0])
    return R * (1 + BOX_SAFETY) + BOX_SAFETY * (float(np.abs(v0).max(initial=0.0)) + 1e-300) if np.isfinite(R) \
        else None


def constraint_box(eq, ineq, n: int, partial: bool = False) -> np.ndarray | None:
    """Per-variable bounds r_i >= |v_i| on the feasible set from the constraints (module docstring, item 1), or
    None when some variable is not bounded this way (``partial``: inf for those variables instead)."""
    r = np.full(n, np.inf)
    lo, hi = np.full(n, -np.inf), np.full(n, np.inf)
    for p, signs in [(h, (1.0,)) for h in ineq] + [(g, (1.0, -1.0)) for g in eq]:
        if not p.terms or p.degree > 2 or p.degree < 1:
            continue
        E = p.exponents()
        S = np.nonzero(E.any(axis=0))[0]
        A, b, c0 = _quadratic_parts(p, S)
        if p.degree == 1 and S.size == 1:
            a, x0 = b[0], -c0 / b[0]
            for sg in signs:                     # sg * (a x + c0) >= 0
                slack = BOX_SAFETY * (abs(x0) + 1e-300)
                if sg * a > 0:
                    lo[S[0]] = max(lo[S[0]], x0 - slack)
                else:
                    hi[S[0]] = min(hi[S[0]], x0 + slack)
            continue
        for sg in signs:                         # sg * p >= 0  <=>  (-sg A) quadratic <= 0
            R = _ball_of(-sg * A, -sg * b, -sg * c0)
            if R is not None:
                r[S] = np.minimum(r[S], R)
    both = np.isfinite(lo) & np.isfinite(hi)
    r = np.where(both, np.minimum(r, np.maximum(np.abs(lo), np.abs(hi))), r)
    return r if partial or np.all(np.isfinite(r)) else None


# ----------------------------------------------------------------------------- a box from a sublevel set of f
def _separable_minorant(f: Polynomial):
    """(constant C, per-variable coefficient arrays P_i (index j: coefficient of t^(2j))) with
    f(v) >= C + sum_i P_i(v_i^2) for every v: a mixed term c v^a of degree k is bounded by weighted AM-GM,
    |v^a| <= sum_i (a_i / k) |v_i|^k, and an odd power by |t|^k <= (t^(k-1) + t^(k+1)) / 2."""
    n = f.nvars
    deg = max(f.degree, 0) + 2
    P = np.zeros((n, deg // 2 + 2))
    C = 0.0

    def add_abs(i, k, weight):                   # weight * |t|^k, weight <= 0 here
        if k % 2 == 0:
            P[i, k // 2] += weight
        else:
            P[i, (k - 1) // 2] += 0.5 * weight
            P[i, (k + 1) // 2] += 0.5 * weight

    for e, c in f.terms.items():
        nz = [i for i, d in enumerate(e) if d]
        if not nz:
            C += c
        elif len(nz) == 1 and e[nz[0]] % 2 == 0:
            P[nz[0], e[nz[0]] // 2] += c
        else:
            k = sum(e)
            for i in nz:
                add_abs(i, k, -abs(c) * e[i] / k)
    return C, P


def _poly_min_nonneg(p: np.ndarray) -> float:
    """min over s >= 0 of sum_j p_j s^j (p_0 first; positive leading coefficient), numerically."""
    cand = [0.0]
    if p.size > 2:
        dr = np.roots((np.arange(1, p.size) * p[1:])[::-1])
        cand += [float(r.real) for r in dr if abs(r.imag) <= 1e-6 * (1 + abs(r)) and r.real > 0]
    return min(float(np.polyval(p[::-1], s)) for s in cand)


def sublevel_box(f: Polynomial, upper: float) -> np.ndarray | None:
    """Per-variable bounds r_i >= |v_i| for every v with f(v) <= ``upper`` (a minimiser has f(v*) <= f(v^) for any
    feasible v^), from the separable minorant of f (:func:`_separable_minorant`); None when some P_i is not
    coercive.  Numerical minima and roots are widened by generous slacks (relative 1e-6 of the coefficients)."""
    if not np.isfinite(upper) or not f.terms:
        return None
    C, P = _separable_minorant(f)
    n = f.nvars
    lead = np.zeros(n, np.int64)
    for i in range(n):
        nzi = np.nonzero(P[i])[0]
        if nzi.size == 0 or P[i, nzi[-1]] <= 0 or nzi[-1] == 0:
            return None
        lead[i] = nzi[-1]
    scale = 1.0 + float(np.abs(P).sum()) + abs(C) + abs(upper)
    slack = 1e-6 * scale
    mins = np.array([_poly_min_nonneg(P[i, :lead[i] + 1]) for i in range(n)]) - slack
    r = np.zeros(n)
    for i in range(n):
        rhs = upper - C - (mins.sum() - mins[i]) + slack
        p = P[i, :lead[i] + 1].copy()
        p[0] -= rhs
        roots = np.roots(p[::-1])
        real = [float(z.real) for z in roots if abs(z.imag) <= 1e-6 * (1 + abs(z))]
        s_max = max([0.0] + real)
        R = np.sqrt(s_max) * (1 + 1e-6) + 1e-9
        if not np.isfinite(R) or np.polyval(p[::-1], R * R) <= 0:
            return None
        r[i] = R
    return r


def unsolved_claim(psatz, lb) -> tuple:
    """(status, lower bound, message) of a solve without a level: an unbounded level ("the set is empty") is a
    claim only when the multiplier q is proven positive (:func:`sospoly.analysis.proof.q_lower_bound`)."""
    from ..status import SolveStatus

    if lb.status == SolveStatus.UNBOUNDED:
        st = psatz.structure
        qmin = q_lower_bound(st, lb.solution) if not st.free or lb.solution is not None else 0.0
        if not qmin > 0:
            return SolveStatus.UNPROVEN, None, ("every level is feasible, but the multiplier q is not proven "
                                                "positive: q may vanish on the set, so nothing is proven")
    return lb.status, lb.lower_bound, lb.message
