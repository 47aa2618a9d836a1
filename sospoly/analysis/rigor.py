"""Rigorous lower bounds from a numerically solved Positivstellensatz certificate.

A solver returns decision values x (c, the multipliers r_k, the Gram entries of s_k) and Gram
matrices G_j of u, accepted when lambda_min(G_j) >= -psd_margin max(1, |G_j|).  The accepted
certificate is exact only up to two defects, and both are accounted for here:

* the **PSD defect** eps_j = max(0, -lambda_min(G_j)) (plus the error bound of the eigenvalue
  computation): G_j + eps_j I is PSD, so b_j^T G_j b_j >= -eps_j ||b_j(v)||^2;
* the **identity residual** e(v) = u(v) - sum_j b_j(v)^T G_j b_j(v), where u is recomputed from x
  and the data theta by its defining formula u = q (f - c) + sum r_k g_k - sum s_k h_k (including a
  bound on the floating-point rounding of that computation).

On the feasible set (g = 0, h >= 0) the identity gives
q (f - c) = sum_j b_j^T G_j b_j + e + sum_k s_k h_k >= -sum_j eps_j ||b_j||^2 - |e| - sum_k eta_k ||b_sk||^2 h_k,
so for every feasible v in a ball ||v|| <= R

    f(v) >= c - margin,   margin = (sum_j eps_j W_j + E + sum_k eta_k W_sk H_k) / q_min,

on the box |v_i| <= r_i (``radius``: one bound per variable, or one for all): W_j = sum_{d in degrees of
b_j} R_j^(2d) >= ||b_j(v)||^2 with R_j^2 = sum of r_i^2 over the block's variables (the monomials of
degree d in b_j satisfy sum_m v^(2m) <= (sum_i v_i^2)^d), E = sum_m |e_m| prod_i r_i^(m_i) >= |e(v)|,
H_k >= |h_k(v)| likewise, and q_min <= q(v) on the box.  If the box holds a global minimiser, c - margin
is a lower bound of the minimum in floating point, up to the stated rounding bounds (the caller knows
the box: e.g. tritools derives it from the objective at a feasible point).

Both functions check the certificate *at the level c they are given*: for a fixed multiplier the level
column of x is set to c before u is recomputed, so a c above the solver's level cannot be reported as
proven (it shows up as residual, or makes the check fail).

:func:`exact_check` verifies a certificate in exact rational arithmetic (``fractions``), for
researchers who want one (Peyrl & Parrilo 2008): the level is lowered by a margin; Gram rows that the
identity forces to zero (a monomial 2b_i whose only Gram entry is the diagonal one and whose coefficient
is 0, e.g. y^4 absent from f) are removed; the Gram matrices, shifted by t I for a few small t, are
projected orthogonally onto the affine space where the identity holds exactly (rationals: the residual of
each monomial spread evenly over its Gram entries); PSD-ness is decided by an exact LDL^T.  A solver's
Gram matrix at the optimum lies on the boundary of the cone (every minimiser is a kernel vector), so
the shift and the lowered level are what give the projection room.
"""
from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from ..algebra.basis import unique_rows


__all__ = ["solution_at_level", "gram_pairs", "psd_defect_of", "block_weight", "poly_sup", "monomial_sup", "u_terms",
           "RigorousBound", "rigorous_psatz_bound", "certificate_residual", "exact_check", "ExactCheck",
           "image_form_stack_margin", "constraint_error_stack",
           # the exact-arithmetic steps of exact_check, shared with sospoly.analysis.exact_face
           "ldl_psd", "shift_multipliers", "exact_multipliers", "gram_entries", "facial_reduction", "exact_u_terms"]

_EPS = np.finfo(float).eps


@dataclass(frozen=True)
class RigorousBound:
    """A lower bound with the PSD defect and the identity residual of its certificate subtracted
    (see the module docstring): f >= ``lower_bound`` on the feasible points of the ball of ``radius``."""
    lower_bound: float          # c - margin (-inf when no bound can be proven on the ball)
    margin: float
    radius: float
    psd_defect: float           # sum_j eps_j W_j(R) + sum_k eta_k W_sk H_k: the PSD part of the margin (before / q_min)
    residual: float             # E(R)
    q_min: float
    #: sum_k sup|r_k| sup|e_k| on the box for equalities known up to coefficient errors e_k (``eq_error``; before
    #: / q_min)
    constraint_error: float = 0.0


def _owner_offsets(structure) -> tuple[np.ndarray, np.ndarray]:
    """(theta offset of each column's owning polynomial, mask of owned columns) for ``m:t`` parameters."""
    prog, slots = structure.program, structure.slots
    owner = np.full(prog.n_vars, -1, np.int64)
    names = [f"r{k}" for k in range(slots.n_eq)] + [f"s{k}" for k in range(slots.n_ineq)]
    for pi, name in enumerate(names, start=1):
        owner[prog.block(name).slice] = pi
    offsets = slots.offsets
    return np.where(owner >= 0, offsets[np.maximum(owner, 0)], -1), owner >= 0


def u_terms(structure, theta, x, c_level):
    """Every contribution to u's coefficients: (exponent rows (T, n), values (T,), weight factors (T,)):
    the coefficient of monomial E[t] gets values[t] (computed in float); the triples let callers redo the
    sum exactly or bound its rounding."""
    u = structure.u
    E, vals = [], []
    const = u.expr
    lin = np.zeros(const.E.shape[0]) + const.const
    if const.rows.size:
        np.add.at(lin, const.rows, const.vals * x[const.cols])
    E.append(const.E), vals.append(lin)
    off_of_col, owned = _owner_offsets(structure)
    for name, expr in u.param_terms.items():
        kind, _, t = name.partition(":")
        coef = expr.const.copy()
        if kind == "c":
            w = np.full(expr.rows.size, c_level)
            coef = coef * c_level
        elif kind == "f":
            th = theta[int(t)]
            w = np.full(expr.rows.size, th)
            coef = coef * th
        else:
            th_idx = off_of_col[expr.cols] + int(t)
            w = np.where(owned[expr.cols], theta[np.maximum(th_idx, 0)], 0.0)
        lin = coef
        if expr.rows.size:
            np.add.at(lin, expr.rows, expr.vals * x[expr.cols] * w)
        E.append(expr.E), vals.append(lin)
    return np.vstack(E), np.concatenate(vals)


def solution_at_level(structure, x, c) -> np.ndarray:
    """A copy of the decision values ``x`` with a fixed multiplier's level column set to ``c`` (free
    multipliers take the level as a parameter instead)."""
    x = np.array(x, float)
    if not structure.free and c is not None:
        x[structure.program.block("c").slice] = c
    return x


def certificate_residual(structure, theta, sol, c_level=None):
    """(monomials (M, n), residual e_m, rounding bound of e_m) of e = u(x) - sum_j b_j^T G_j b_j, u at level
    ``c_level`` (for a fixed multiplier the level column of x is set to it; None: x's own level, 0 for a
    free multiplier)."""
    x = solution_at_level(structure, sol.x, c_level)
    E_u, v_u = u_terms(structure, theta, x, 0.0 if c_level is None else c_level)
    u = structure.u
    gb = u.gram
    G_all = np.concatenate([gram_pairs(sol.grams[name], b.size) for name, b in zip(u.block_names(), gb.blocks)])
    w = np.where(gb.pair_diag, 1.0, 2.0)
    E_g = gb.products[gb.pair_monomial]
    E = np.vstack([E_u, E_g])
    vals = np.concatenate([v_u, -w * G_all])
    uniq, inv = unique_rows(E, return_inverse=True)
    e = np.zeros(uniq.shape[0])
    np.add.at(e, inv, vals)
    a = np.zeros(uniq.shape[0])
    np.add.at(a, inv, np.abs(vals))
    count = np.bincount(inv, minlength=uniq.shape[0])
    rounding = (count + 4) * _EPS * a * 4.0          # sums of products of a few floats, generous factor
    return uniq, e, rounding


def gram_pairs(G: np.ndarray, s: int) -> np.ndarray:
    from ..algebra.svec import triu_pairs

    i, j = triu_pairs(s)
    return 0.5 * (G[i, j] + G[j, i])


def block_weight(basis: np.ndarray, r: np.ndarray, ball: bool, cap: float | None = None) -> float:
    """sum over the degrees d present in ``basis`` of R^(2d): a bound of ||b(v)||^2 (sum_{|m| = d} v^(2m) <=
    (sum_i v_i^2)^d), with R^2 the sum of r_i^2 over the basis' variables on the box |v_i| <= r_i, or the
    ball's R^2 (``ball``: every r_i is the ball's radius); at most ``cap``^2 when a ball ||v|| <= cap holds
    too."""
    used = np.any(basis > 0, axis=0)
    R2 = float(r[0] ** 2) if ball else float(np.sum(r[used] ** 2))
    if cap is not None:
        R2 = min(R2, float(cap) ** 2)
    return float(sum(R2 ** d for d in np.unique(basis.sum(axis=1))))


def monomial_sup(E: np.ndarray, r: np.ndarray) -> np.ndarray:
    """prod_i r_i^(m_i) for every exponent row m of E (k, n): the sup of |v^m| on the box |v_i| <= r_i (r (n,));
    a variable absent from m contributes 1 whatever its radius (inf included)."""
    E, r = np.asarray(E), np.asarray(r, float)
    with np.errstate(over="ignore", invalid="ignore"):
        return np.prod(np.where(E > 0, r[None, :] ** E, 1.0), axis=1)


def psd_defect_of(G: np.ndarray) -> float:
    if G.size == 0:
        return 0.0
    lam = np.linalg.eigvalsh(0.5 * (G + G.T))
    err = 8 * G.shape[0] * _EPS * max(float(np.abs(lam).max()), 1e-300)
    return max(0.0, -float(lam[0])) + err


def poly_sup(p, r: np.ndarray) -> float:
    """A bound of |p(v)| on the box |v_i| <= r_i."""
    if not p.terms:
        return 0.0
    return float(np.sum(np.abs(p.coefficients()) * monomial_sup(p.exponents(), r)))


def _q_min(structure, sol, r: np.ndarray) -> float:
    """A lower bound of q on the box (q fixed: 1 + ... with non-negative even terms, or a user q)."""
    if structure.free:
        Q = sol.grams.get("q")
        return float(np.linalg.eigvalsh(Q)[0]) - 8 * Q.shape[0] * _EPS * float(np.abs(Q).max()) if Q is not None \
            else 0.0
    q = structure.q
    E, c = q.exponents(), q.coefficients()
    const = float(c[E.sum(axis=1) == 0].sum()) if E.size else 0.0
    even_pos = np.all(E % 2 == 0, axis=1) & (c > 0)
    rest = ~even_pos & (E.sum(axis=1) > 0)
    return const - float(np.sum(np.abs(c[rest]) * monomial_sup(E[rest], r)))


def rigorous_psatz_bound(psatz, sol, c: float, radius, ball: float | None = None, eq_error=None) -> RigorousBound:
    """c minus the margin of the module docstring, for a solved fixed- or free-q Psatz certificate
    (``psatz`` a PsatzProblem or compiled instance; ``sol`` its ProgramSolution; ``c`` its level; ``radius``
    a bound of ||v|| (one number: a ball) or of every |v_i| (one per variable: a box); ``ball`` optionally a
    bound of ||v|| that holds on the box's minimiser too (it caps each block's R^2: a box of many variables
    has corners far outside a ball of the same per-variable radius)).

    ``eq_error``: for equalities computed from inexact data, one bound e_k >= 0 per equality of |g_k(v)| at every
    point v of the box that is feasible for the *true* constraints (0 for an exact one; e.g. the coefficient errors
    of g_k times the box's monomial bounds).  There the identity leaves sum_k r_k(v) g_k(v), so the margin gains
    sum_k sup|r_k| e_k (``constraint_error``): the bound holds for the true feasible set, not the computed one."""
    structure = psatz.structure
    if not _check_rigor_inputs(sol, c, radius, ball) or sol.x is None or \
            any(name not in (sol.grams or {}) for name in structure.u.block_names()):
        # (a solve that returned no iterate, or one without u's Gram matrices -- an inaccurate solve that stopped
        # before a certificate: nothing to prove, review 39b; was a KeyError)
        return RigorousBound(-np.inf, np.inf, float(np.max(np.asarray(radius, float))), np.inf, np.inf, 0.0)
    theta = np.asarray(psatz.theta, float)
    n = len(structure.gens)
    cap = None if ball is None else float(ball)
    ball = np.ndim(radius) == 0
    r = np.broadcast_to(np.asarray(radius, float), (n,)).copy()
    R = float(r[0]) if ball else float(np.sqrt(np.sum(r ** 2)))
    E_mono, e, rnd = certificate_residual(structure, theta, sol, c)
    resid = float(np.sum((np.abs(e) + rnd) * monomial_sup(E_mono, r)))
    psd = 0.0
    u = structure.u
    for name, blk in zip(u.block_names(), u.gram.blocks):
        psd += psd_defect_of(sol.grams[name]) * block_weight(blk.b, r, ball, cap)
    prog = structure.program
    x = np.asarray(sol.x, float)
    ineq = psatz.ineq if hasattr(psatz, "ineq") else \
        (structure.slots.ineq_polynomials(theta) if structure.slots.n_ineq else ())   # built once, not per k
    for k in range(structure.slots.n_ineq):
        blk = prog.block(f"s{k}")
        S = np.zeros((blk.gram.size, blk.gram.size))
        S[blk.gram.pair_i, blk.gram.pair_j] = x[blk.slice]
        S[blk.gram.pair_j, blk.gram.pair_i] = x[blk.slice]
        psd += psd_defect_of(S) * block_weight(blk.gram.b, r, ball, cap) * poly_sup(ineq[k], r)
    cerr = _constraint_error(structure, x, r, eq_error)
    qmin = _q_min(structure, sol, r)
    if not qmin > 0:
        return RigorousBound(-np.inf, np.inf, R, psd, resid, qmin, cerr)
    with np.errstate(over="ignore", invalid="ignore"):
        margin = (psd + resid + cerr) / qmin
    if not np.isfinite(margin):
        return RigorousBound(-np.inf, np.inf, R, psd, resid, qmin, cerr)
    return RigorousBound(float(c) - margin, margin, R, psd, resid, qmin, cerr)


def _constraint_error(structure, x: np.ndarray, r: np.ndarray, eq_error) -> float:
    """sum_k sup|r_k| e_k on the box |v_i| <= r_i (:func:`rigorous_psatz_bound`'s ``eq_error``)."""
    if eq_error is None:
        return 0.0
    if isinstance(eq_error, (str, bytes)) or not np.iterable(eq_error):
        raise TypeError(f"rigorous_psatz_bound eq_error must be a sequence of numbers, got {type(eq_error).__name__}")
    try:
        e = np.asarray([0.0 if v is None else v for v in eq_error], dtype=float)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"rigorous_psatz_bound eq_error must hold real numbers (None for an exact equality): {exc}") \
            from None
    if e.ndim != 1 or e.size != structure.slots.n_eq:
        raise ValueError(f"rigorous_psatz_bound eq_error needs one bound per equality ({structure.slots.n_eq}), got "
                         f"{e.size}")
    if np.any(np.isnan(e)) or np.any(e < 0):
        raise ValueError("rigorous_psatz_bound eq_error must hold non-negative bounds")
    total = 0.0
    with np.errstate(over="ignore", invalid="ignore"):
        for k in np.flatnonzero(e):
            total += _linpoly_sup(structure.r[k], x, r) * float(e[k])
    return float(total) if not np.isnan(total) else np.inf


def _linpoly_sup(p, x: np.ndarray, r: np.ndarray) -> float:
    """A bound of |p(v)| on the box for the multiplier ``p`` (a LinPoly) at decision values ``x``."""
    coef = np.array(p.const, float)
    if p.rows.size:
        np.add.at(coef, p.rows, p.vals * x[p.cols])
    return float(np.sum(np.abs(coef) * monomial_sup(p.E, r))) if coef.size else 0.0


def _check_rigor_inputs(sol, c, radius, ball) -> bool:
    """TypeError / ValueError naming what is wrong in :func:`rigorous_psatz_bound`'s inputs (review 25b F7: a
    negative or NaN radius gave a bound or NaN; ``sol=None`` an AttributeError); False where no bound can be proven
    (an infinite radius or a non-finite level: the caller gets -inf, as for any unprovable margin)."""
    if sol is None or not hasattr(sol, "grams") or not hasattr(sol, "x"):
        raise TypeError(f"rigorous_psatz_bound needs a solved ProgramSolution, got {type(sol).__name__}")
    if isinstance(c, (bool, np.bool_)) or not isinstance(c, (int, float, np.floating, np.integer)):
        raise TypeError(f"rigorous_psatz_bound level c must be a number, got {type(c).__name__}")
    r = np.asarray(radius, float) if not isinstance(radius, (bool, np.bool_)) else np.array(np.nan)
    if r.size == 0 or np.any(np.isnan(r)) or not np.all(r >= 0):
        raise ValueError(f"rigorous_psatz_bound radius must be non-negative (one number or one per variable), got "
                         f"{radius!r}")
    if ball is not None and (np.isnan(ball) or ball < 0):
        raise ValueError(f"rigorous_psatz_bound ball must be non-negative, got {ball!r}")
    return bool(np.isfinite(c) and np.all(np.isfinite(r)))


def constraint_error_stack(structure, X, radius, eq_error) -> np.ndarray:
    """(B,) sum_k sup|r_k| e_k for B solutions of one structure at once: the ``eq_error`` charge of
    :func:`rigorous_psatz_bound` (its ``_constraint_error``) for decision vectors X (B, columns) -- the program's
    variables first, as lowered (:mod:`sospoly.lowering.conic`) -- each multiplier's sup on the box |v_i| <= R_b
    (``radius`` (B,) or a number: every monomial v^E is at most R_b^|E| there) and ``eq_error`` (B, K) bounds of
    |g_k(v)| at the points feasible for the true constraints.  The sums are rounded up; inf where not finite."""
    X = np.asarray(X, float)
    B = X.shape[0]
    e = np.broadcast_to(np.asarray(eq_error, float), (B, structure.slots.n_eq))
    R = np.broadcast_to(np.asarray(radius, float), (B,))
    total = np.zeros(B)
    with np.errstate(over="ignore", invalid="ignore"):
        for k in np.flatnonzero(np.any(e != 0, axis=0)):
            p = structure.r[k]
            coef = np.tile(np.asarray(p.const, float), (B, 1))
            if p.rows.size:
                np.add.at(coef.T, p.rows, (p.vals * X[:, p.cols]).T)
            sup = R[:, None] ** np.sum(p.E, axis=1)[None, :]
            total = total + np.sum(np.abs(coef) * sup, axis=1) * e[:, k]
        total = total * (1 + 4 * (structure.slots.n_eq + 8) * _EPS)
    return np.where(np.isnan(total), np.inf, total)


def image_form_stack_margin(eigenvalues, gram_error, weight, q_min=1.0) -> np.ndarray:
    """The margin of the module docstring for a stack of single-block certificates in the image form (the
    coefficient identity u = b^T G(x) b holds for every x by construction, so only the computation of G and
    its PSD defect count): ``(max(0, -lambda_min) + eigen error + gram_error) * weight / q_min``.

    ``eigenvalues`` (B, n) ascending, of the computed G; ``gram_error`` (B,) a bound of ||G_computed - G(x)||_2;
    ``weight`` (B,) a bound of ||b(v)||^2 on a region that holds a minimiser; ``q_min`` a lower bound of q
    there.  Subtracting it from c gives a lower bound of the minimum in floating point."""
    lam = np.asarray(eigenvalues, float)
    n = lam.shape[-1]
    defect = np.maximum(0.0, -lam[..., 0]) + 8 * n * _EPS * np.maximum(np.abs(lam).max(axis=-1), 1e-300)
    return (defect + np.asarray(gram_error, float)) * np.asarray(weight, float) / q_min


# ----------------------------------------------------------------------------- exact rational check
@dataclass(frozen=True)
class ExactCheck:
    """Outcome of :func:`exact_check`: ``ok`` when the certificate proves f >= ``level`` in exact arithmetic."""
    ok: bool
    level: float            # the level c' proven: f >= c' on the feasible set (when ok)
    message: str = ""


def ldl_psd(M: list) -> bool:
    """Exact PSD test of a symmetric rational matrix (list of lists of Fractions) by LDL^T with
    symmetric pivoting: PSD iff every pivot is >= 0 and a zero pivot has a zero row."""
    A = [row[:] for row in M]
    n = len(A)
    active = list(range(n))
    while active:
        k = max(active, key=lambda i: A[i][i])
        piv = A[k][k]
        if piv < 0:
            return False
        active.remove(k)
        if piv == 0:
            if any(A[k][j] != 0 for j in active):
                return False
            continue
        for i in active:
            if A[i][k] == 0:
                continue
            f = A[i][k] / piv
            for j in active:
                if A[k][j] != 0:
                    A[i][j] -= f * A[k][j]
    return True


#: the shifts t (relative to the margin) tried by :func:`exact_check`, largest first: the shift must exceed the
#: solver's PSD defect (~1e-10) and stay below the margin the lowered level provides on the minimisers'
#: directions (t = margin itself can undo it).
EXACT_SHIFTS = (1e-1, 1e-2, 1e-3, 1e-4, 1e-5, 0.0)
#: an inequality multiplier s_k with lambda_min below -SHIFT_LIMIT max(1, max|S|) is refused outright (the
#: PSD margin of the numerical check); above it, s_k is shifted to PSD and u recomputed with the shift.
SHIFT_LIMIT = 1e-6


def exact_check(psatz, sol, c: float, margin: float | None = None) -> ExactCheck:
    """Verify in exact rational arithmetic that f >= c - margin on the feasible set.

    The certificate's numbers (decision values x with the level set to ``c``, Gram matrices, data theta)
    are read as exact rationals (every float is one) and u + margin q is recomputed exactly; the
    inequality multipliers s_k are shifted by their PSD defect (u changes accordingly, exactly); Gram
    rows the identity forces to zero are removed; for t in ``margin * EXACT_SHIFTS`` the Gram matrices
    G + t I are projected onto the affine space of exact identities and tested by exact LDL^T (see the
    module docstring).  ``ok`` is True when some t gives PSD matrices: a proof, whatever the t.  ``level``
    is then c - margin rounded down to a float.  Fixed multipliers only, and only a q proven positive for every v
    (:func:`sospoly.analysis.proof.q_lower_bound`; q = (y - 1)^2 on {y = 1} would prove any level); ``margin``
    defaults to 1e-7 max(1, |c|).  Cost grows like the cube of the Gram side with rational arithmetic: meant for
    small programs."""
    if sol is None or getattr(sol, "x", None) is None or not getattr(sol, "grams", None):
        status = getattr(getattr(sol, "status", None), "value", "no solution")
        raise ValueError(f"exact_check: the solution (status {status}) carries no certificate to check; it needs a "
                         "solved program's decision values and Gram matrices")
    structure = psatz.structure
    if structure.free:
        return ExactCheck(False, float(c), "exact checks are implemented for fixed multipliers")
    from .proof import q_lower_bound

    if not q_lower_bound(structure, sol) > 0:       # q (f - c) >= 0 proves f >= c only where q > 0 (review 26a F3)
        return ExactCheck(False, float(c), "the multiplier q is not proven positive everywhere (a positive constant "
                                           "plus even powers with positive coefficients): nothing is proven")
    margin = 1e-7 * max(1.0, abs(c)) if margin is None else float(margin)
    if not (np.isfinite(c) and np.isfinite(margin) and margin >= 0):
        return ExactCheck(False, float(c), "c and margin must be finite, margin >= 0")
    theta = np.asarray(psatz.theta, float)
    x = solution_at_level(structure, sol.x, c)
    why = shift_multipliers(structure, x) or exact_multipliers(structure, x)
    if why:
        return ExactCheck(False, float(c), why)
    # the target coefficients p = u(x) + margin q, exactly
    coef: dict = {}
    exact_u_terms(structure, theta, x, coef)
    for e, cq in structure.q.terms.items():
        coef[e] = coef.get(e, Fraction(0)) + Fraction(margin) * Fraction(cq)
    u = structure.u
    pairs = gram_entries(u)
    for m, val in coef.items():
        if val != 0 and m not in pairs:
            return ExactCheck(False, float(c), f"the residual has monomial {m} outside every Gram block")
    live = facial_reduction(u, pairs, coef)
    if isinstance(live, str):
        return ExactCheck(False, float(c), live)
    return _proof_by_shifts([np.asarray(sol.grams[name], float) for name in u.block_names()], live, pairs, coef,
                            c, margin)


def shift_multipliers(structure, x: np.ndarray) -> str | None:
    """Shift each inequality multiplier s_k of ``x`` (in place) by twice its PSD defect on the diagonal (plus a
    few ulps); the reason it cannot be used when its defect exceeds ``SHIFT_LIMIT`` of its scale."""
    prog = structure.program
    for k in range(structure.slots.n_ineq):
        blk = prog.block(f"s{k}")
        pi, pj = blk.gram.pair_i, blk.gram.pair_j
        vals = x[blk.slice]
        S = np.zeros((blk.gram.size, blk.gram.size))
        S[pi, pj] = vals
        S[pj, pi] = vals
        lam = float(np.linalg.eigvalsh(S)[0]) if S.size else 0.0
        if lam < -SHIFT_LIMIT * max(1.0, float(np.abs(S).max())):
            return f"multiplier s{k} is not PSD (lambda_min {lam:.3g})"
        if lam < 0:
            x[blk.slice] = np.where(pi == pj, vals + 2.0 * (-lam) + _EPS * float(np.abs(S).max()), vals)
    return None


def exact_multipliers(structure, x: np.ndarray) -> str | None:
    """The exact LDL^T test of every inequality multiplier's Gram matrix read from ``x`` as rationals; the
    reason of the first that is not PSD."""
    prog = structure.program
    for k in range(structure.slots.n_ineq):
        blk = prog.block(f"s{k}")
        s = blk.gram.size
        S = [[Fraction(0)] * s for _ in range(s)]
        for p, val in enumerate(x[blk.slice]):
            i, kk = int(blk.gram.pair_i[p]), int(blk.gram.pair_j[p])
            S[i][kk] = S[kk][i] = Fraction(float(val))
        if not ldl_psd(S):
            return f"multiplier s{k} is not PSD"
    return None


def gram_entries(u) -> dict:
    """monomial -> every Gram entry (block j, i <= k) whose product b_i b_k it is."""
    pairs: dict = {}
    for j, blk in enumerate(u.gram.blocks):
        for p in range(blk.n_pairs):
            i, k = int(blk.pair_i[p]), int(blk.pair_j[p])
            m = tuple(int(t) for t in blk.products[blk.pair_monomial[p]])
            pairs.setdefault(m, []).append((j, i, k))
    return pairs


def facial_reduction(u, pairs: dict, coef: dict) -> list | str:
    """The live rows of each Gram block: a monomial whose remaining entries are all diagonal and whose
    coefficient is 0 forces those diagonal entries, hence their rows, to 0 (PSD); a negative one is
    infeasible (returned as the reason, a str)."""
    live = [np.ones(blk.size, bool) for blk in u.gram.blocks]
    changed = True
    while changed:
        changed = False
        for m, entries in pairs.items():
            alive = [(j, i, k) for j, i, k in entries if live[j][i] and live[j][k]]
            if alive and all(i == k for _, i, k in alive):
                target = coef.get(m, Fraction(0))
                if target < 0:
                    return f"monomial {m} has a negative coefficient and only diagonal Gram entries"
                if target == 0:
                    for j, i, _ in alive:
                        live[j][i] = False
                    changed = True
    return live


def _proof_by_shifts(G0: list, live: list, pairs: dict, coef: dict, c: float, margin: float) -> ExactCheck:
    """Try the shifts t (4 x the live Gram matrices' defect, then ``margin * EXACT_SHIFTS``, largest first):
    the first t whose projected G + t I is PSD proves f >= c - margin, reported rounded down to a float."""
    lam = min((float(np.linalg.eigvalsh(G[np.ix_(lv, lv)])[0]) for G, lv in zip(G0, live) if lv.any()),
              default=0.0)
    shifts = sorted({max(0.0, 4.0 * -lam)} | {margin * r for r in EXACT_SHIFTS}, reverse=True)
    G0q = [[[Fraction(float(v)) for v in row] for row in G] for G in G0]
    for t in shifts:
        if _projected_psd(G0q, live, pairs, coef, Fraction(t)):
            level = Fraction(float(c)) - Fraction(margin)
            out = float(level)
            if Fraction(out) > level:
                out = float(np.nextafter(out, -np.inf))
            return ExactCheck(True, out, f"exact identity with PSD Gram matrices (shift t = {t:.3g})")
    return ExactCheck(False, float(c), "no projected Gram matrix is PSD (the level may be above what the "
                                       "certificate proves, or the margin too small)")


def _projected_psd(G0q: list, live: list, pairs: dict, coef: dict, t: Fraction) -> bool:
    """Are the orthogonal projections of G0 + t I (live rows only) onto the exact identities PSD?  Each
    monomial's residual p_m - sum_e w_e G_e is spread evenly (G_e += r_m / sum_e w_e) over its live entries."""
    G = [[row[:] for row in Gj] for Gj in G0q]
    for j, Gj in enumerate(G):
        for i in range(len(Gj)):
            if live[j][i]:
                Gj[i][i] += t
    for m, entries in pairs.items():
        alive = [(j, i, k) for j, i, k in entries if live[j][i] and live[j][k]]
        r = coef.get(m, Fraction(0)) - sum((1 if i == k else 2) * G[j][i][k] for j, i, k in alive)
        if not alive:
            if r != 0:
                return False
            continue
        step = r / sum(1 if i == k else 2 for _, i, k in alive)
        for j, i, k in alive:
            G[j][i][k] += step
            if i != k:
                G[j][k][i] += step
    for j, Gj in enumerate(G):
        idx = [i for i in range(len(Gj)) if live[j][i]]
        if idx and not ldl_psd([[Gj[a][b] for b in idx] for a in idx]):
            return False
    return True


def exact_u_terms(structure, theta, x, coef: dict) -> None:
    """Add u(x)'s coefficients, computed exactly in Fractions, into ``coef`` (monomial tuple -> Fraction)."""
    u = structure.u
    off_of_col, owned = _owner_offsets(structure)
    F = Fraction

    def add(E, row, value):
        m = tuple(int(t) for t in E[row])
        coef[m] = coef.get(m, F(0)) + value

    parts = [(None, u.expr)] + list(u.param_terms.items())
    for name, expr in parts:
        kind, _, t = (name or "").partition(":")
        weight = F(1) if name is None else (F(float(theta[int(t)])) if kind == "f" else None)
        for r in np.nonzero(expr.const)[0]:
            if kind == "m":
                continue                       # multiplier parameters carry no constants
            add(expr.E, r, F(float(expr.const[r])) * (weight if weight is not None else F(1)))
        for r, col, val in zip(expr.rows, expr.cols, expr.vals):
            if kind == "m":
                if not owned[col]:
                    continue
                w = F(float(theta[off_of_col[col] + int(t)]))
            else:
                w = weight
            add(expr.E, r, F(float(val)) * F(float(x[col])) * w)
