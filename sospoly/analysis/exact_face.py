"""Exact proofs of a lower bound whose Gram matrices lie on a singular face of the PSD cone.

The shifted and projected proofs (:func:`sospoly.analysis.proof.global_psatz_bound`,
:func:`sospoly.analysis.rigor.exact_check`) lower the level c by a margin m and look for a Gram matrix of
u' = u + m q that is PSD after a small shift t I.  That fails, however small the solver's defect, when *every*
Gram matrix of u' is singular along the same vector w, whatever the level: Rosenbrock's
(1 - x)^2 + 100 (y - x^2)^2 on the Newton basis b = (1, x, y, x^2) fixes the entries of y^2, x^2 y and x^4 at 100,
-200 / 2, 100, so Q (e_y + e_x2) = 0 for every Gram matrix Q, and any shift or residual spread on those rows
breaks PSD-ness.

**Facial reduction** (Borwein and Wolkowicz 1981; Permenter and Parrilo 2018, "Partial facial reduction") certifies
such a face with a moment vector: if Y = w w^T is a *moment matrix* of the certificate -- Y_ik depends only on the
monomial b_i b_k (y_m), and is 0 on every entry of another Gram block reaching m -- and <y, u'> = 0, then every
Gram matrix Q of u' has <Y, Q> = <y, u'> = 0, so Q PSD forces Q w = 0.  Here (Rosenbrock): y = 1 on y^2, x^2 y, x^4,
<y, u'> = 100 - 200 + 100 = 0, exactly.

:func:`face_exact_check`:

1. the certificate at the lowered level, read as exact rationals (as :func:`~sospoly.analysis.rigor.exact_check`:
   fixed multipliers, inequality multipliers shifted to PSD, rows forced to zero removed);
2. candidate vectors w: the reduced row echelon form of the span of the eigenvectors of the k smallest eigenvalues
   of each Gram block (k = 1 .. ``MAX_FACE_DIMENSION``), entries rationalised with denominators <=
   ``MAX_DENOMINATOR``, each kept only when the moment-matrix test above holds exactly;
3. a Gram matrix with the identity exact *and* Q w = 0 for every kept w, in rationals: the reduced row echelon
   form of that linear system (diagonal entries first) fixes its pivot entries from the others, which are taken
   from the solver's Gram matrix shifted by t I and projected onto the face (in floats: any values are sound);
4. exact LDL^T of every block: PSD proves u' >= 0, i.e. q (f - c + m) >= 0 on the feasible set, f >= c - m where
   q > 0 (the caller proves q > 0, :func:`sospoly.analysis.proof.q_lower_bound`).

Steps 2 and 3 are heuristics that only choose *which* rational Gram matrix to test; step 4 decides, exactly.
Rational arithmetic costs grow fast with the size of the system: only programs with at most
``MAX_EXACT_ENTRIES`` live Gram entries are tried.
"""
from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from .rigor import (exact_multipliers, exact_u_terms, facial_reduction, gram_entries, ldl_psd,
                    shift_multipliers, solution_at_level)

__all__ = ["FaceCheck", "face_exact_check", "MAX_DENOMINATOR", "MAX_EXACT_ENTRIES", "MAX_GRAM_PAIRS", "FACE_SHIFTS"]

#: kernel vectors are rationalised with denominators up to this (structural faces have small rational vectors)
MAX_DENOMINATOR = 1024
#: ... when every entry of the echelon form lies within this of such a rational (a loose guess: the exact test of
#: each candidate decides)
ROUNDING = 1e-3
#: candidate face vectors come from the spans of the k = 1 .. this many eigenvectors of the smallest eigenvalues
MAX_FACE_DIMENSION = 4
#: the exact system is set up only for certificates with at most this many live Gram entries (rational arithmetic)
MAX_EXACT_ENTRIES = 120
#: ... and only for certificates with at most this many Gram entries before the rows forced to zero are removed
#: (the rational arithmetic of reading the certificate costs that much already)
MAX_GRAM_PAIRS = 500
#: shifts t on the face, relative to the margin, largest first (as :data:`sospoly.analysis.rigor.EXACT_SHIFTS`)
FACE_SHIFTS = (1e-1, 1e-2, 1e-3, 0.0)


@dataclass(frozen=True)
class FaceCheck:
    """Outcome of :func:`face_exact_check`: ``ok`` when f >= ``level`` is proven exactly (``margin`` m = c - level,
    ``faces`` the number of face vectors w used)."""
    ok: bool
    level: float
    margin: float
    faces: int
    message: str = ""


def _float_rref(A: np.ndarray) -> np.ndarray:
    """The reduced row echelon form of A (partial pivoting; rows below 1e-8 of the largest entry dropped)."""
    A = np.array(A, float)
    rows, cols = A.shape
    top = max(float(np.abs(A).max(initial=0.0)), 1e-300)
    r = 0
    for c in range(cols):
        if r == rows:
            break
        p = r + int(np.argmax(np.abs(A[r:, c])))
        if abs(A[p, c]) <= 1e-8 * top:
            continue
        A[[r, p]] = A[[p, r]]
        A[r] /= A[r, c]
        others = np.arange(rows) != r
        A[others] -= np.outer(A[others, c], A[r])
        r += 1
    return A[:r]


def _rational(v: np.ndarray) -> list | None:
    """``v`` as Fractions with denominators <= MAX_DENOMINATOR, or None when some entry is not that close to one."""
    out = []
    for a in v:
        q = Fraction(float(a)).limit_denominator(MAX_DENOMINATOR)
        if abs(float(q) - float(a)) > ROUNDING:
            return None
        out.append(q)
    return out


def _is_face(w: dict, j: int, pairs: dict, coefs: tuple, live: list) -> bool:
    """Is Y = w w^T (block j; ``w`` maps live rows to Fractions) a moment matrix with <y, p> = 0 for each p in
    ``coefs`` (u at the solver's level and q: then <y, u + m q> = 0 at every margin m; module docstring)?  Entries
    on rows forced to zero (not ``live``) carry nothing."""
    totals = [Fraction(0)] * len(coefs)
    for m, entries in pairs.items():
        vals = {(w.get(i, 0) * w.get(k, 0)) if jj == j else Fraction(0) for jj, i, k in entries
                if live[jj][i] and live[jj][k]}
        if not vals:
            continue
        if len(vals) > 1:
            return False
        y = vals.pop()
        if y != 0:
            totals = [tot + y * coef.get(m, Fraction(0)) for tot, coef in zip(totals, coefs)]
    return not any(totals)


def _face_vectors(grams: list, live: list, pairs: dict, coefs: tuple) -> list:
    """(block, {row: Fraction}) of every candidate w that passes :func:`_is_face` (step 2), from the spans of the
    k = 1 .. ``MAX_FACE_DIMENSION`` eigenvectors of each block's smallest eigenvalues."""
    out, seen = [], set()
    for j, (G, lv) in enumerate(zip(grams, live)):
        idx = np.flatnonzero(lv)
        if idx.size < 2:
            continue
        _, U = np.linalg.eigh(0.5 * (G[np.ix_(idx, idx)] + G[np.ix_(idx, idx)].T))
        for k in range(1, min(idx.size, MAX_FACE_DIMENSION + 1)):
            for row in _float_rref(U[:, :k].T):
                q = _rational(row)
                if q is None or not any(q):
                    continue
                w = {int(i): v for i, v in zip(idx, q) if v != 0}
                key = (j, tuple(sorted(w.items())))
                if key not in seen and _is_face(w, j, pairs, coefs, live):
                    out.append((j, w))
                seen.add(key)
    return out


def _rref_exact(rows: list, n_cols: int) -> tuple[list, list]:
    """Reduced row echelon form of sparse rational rows (dicts column -> Fraction; the right-hand sides sit in
    columns >= n_cols and are never pivots), pivoting on columns in increasing order.  Returns (pivot rows,
    pivot columns); rows reduced to right-hand sides only are kept as pivot column -1 (consistency checks)."""
    rows = [dict(r) for r in rows if r]
    pivots, cols = [], []
    for c in range(n_cols):
        cand = [r for r in rows if r.get(c, 0) != 0]
        if not cand:
            continue
        piv = min(cand, key=len)
        rows.remove(piv)
        inv = 1 / piv[c]
        piv = {k: v * inv for k, v in piv.items()}
        for r in rows + pivots:
            f = r.get(c, 0)
            if f != 0:
                for k, v in piv.items():
                    nv = r.get(k, 0) - f * v
                    if nv == 0:
                        r.pop(k, None)
                    else:
                        r[k] = nv
        pivots.append(piv)
        cols.append(c)
    return pivots + [r for r in rows if r], cols + [-1] * sum(1 for r in rows if r)


@dataclass
class _System:
    """The exact linear system of step 3: unknown k is Gram entry ``entries[k]`` = (block, i, k), i <= k."""
    entries: list
    pivots: list
    pivot_cols: list
    rhs0: int
    rhsq: int


def _system(u, live: list, pairs: dict, coef0: dict, coefq: dict, faces: list) -> _System | str:
    """The identity (right-hand side coef0 + m coefq) and the face equations Q w = 0, in echelon form."""
    entries = [(j, i, k) for j, blk in enumerate(u.gram.blocks) for i, k in zip(blk.pair_i.tolist(),
                                                                                blk.pair_j.tolist())
               if live[j][i] and live[j][k]]
    entries.sort(key=lambda e: (e[1] != e[2],))          # diagonal entries first: they take the corrections
    col = {e: n for n, e in enumerate(entries)}
    N = len(entries)
    rows = []
    for m, ents in pairs.items():
        r = {col[(j, i, k)]: Fraction(1 if i == k else 2) for j, i, k in ents if (j, i, k) in col}
        for c_, v in ((N, coef0.get(m, Fraction(0))), (N + 1, coefq.get(m, Fraction(0)))):
            if v != 0:
                r[c_] = -v
        if r:
            rows.append(r)
    for j, w in faces:
        for i in np.flatnonzero(live[j]).tolist():
            r = {}
            for k, wk in w.items():
                key = (j, min(i, k), max(i, k))
                if key in col:
                    r[col[key]] = r.get(col[key], 0) + wk
            if any(v != 0 for v in r.values()):
                rows.append(r)
    pivots, pcols = _rref_exact(rows, N)
    return _System(entries, pivots, pcols, N, N + 1)


def _solve_psd(sys_: _System, free_values: dict, margin: Fraction, live: list) -> bool:
    """Pivot entries from the free ones (``free_values``: entry -> Fraction), then exact LDL^T of every block."""
    vals = dict(free_values)
    for piv, c in zip(sys_.pivots, sys_.pivot_cols):
        const = -(piv.get(sys_.rhs0, 0) + margin * piv.get(sys_.rhsq, 0))    # row: x_c + sum a x_f - rhs = 0
        if c < 0:
            if const != 0:
                return False
            continue
        vals[sys_.entries[c]] = const - sum(v * vals[sys_.entries[k]] for k, v in piv.items()
                                            if k < sys_.rhs0 and k != c)
    for j, lv in enumerate(live):
        idx = np.flatnonzero(lv).tolist()
        if not idx:
            continue
        M = [[vals.get((j, min(a, b), max(a, b)), Fraction(0)) for b in idx] for a in idx]
        if not ldl_psd(M):
            return False
    return True


def _free_values(sys_: _System, grams: list, live: list, faces: list, t: float) -> dict:
    """Float starting values (G + t I on the live rows, projected onto the face's complement) as Fractions."""
    out = {}
    pivot = set(c for c in sys_.pivot_cols if c >= 0)
    for j, G in enumerate(grams):
        G = 0.5 * (G + G.T) + t * np.diag(live[j].astype(float))
        W = [np.array([float(w.get(i, 0)) for i in range(G.shape[0])]) for jj, w in faces if jj == j]
        if W:
            Wm = np.array(W).T
            P = np.eye(G.shape[0]) - Wm @ np.linalg.pinv(Wm)
            G = P @ G @ P
        grams[j] = G
    for n, (j, i, k) in enumerate(sys_.entries):
        if n not in pivot:
            out[(j, i, k)] = Fraction(float(grams[j][i, k]))
    return out


def _reduction_coefficients(coef0: dict, coefq: dict) -> dict:
    """The coefficients that decide the facial reduction at every margin m: u + m q has coef0 + m coefq, so a
    monomial of q is positive there once m is large enough (its rows stay live: the exact LDL^T decides), and only
    a monomial absent from q keeps coef0 at every margin (0: its diagonal rows are forced to zero; negative: no
    margin proves the level).  Review 39b: x^2 + 100 (y - x^2)^2, minimum 0 at the origin, had "monomial (0, 0) has
    a negative coefficient" at the solver's level 3.8e-9 and no bound."""
    out = dict(coef0)
    for m, v in coefq.items():
        if v > 0 or (v != 0 and out.get(m, Fraction(0)) > 0):
            out[m] = Fraction(1)
    return out


def face_exact_check(psatz, sol, c: float, margins) -> FaceCheck:
    """The proof of the module docstring at the levels c - m, m in ``margins`` (smallest first); the first proven
    level wins."""
    structure = psatz.structure
    if structure.free or sol is None or sol.x is None:
        return FaceCheck(False, -np.inf, np.inf, 0, "exact face checks need a fixed multiplier and a solution")
    u = structure.u
    if u.gram.n_pairs > MAX_GRAM_PAIRS:
        return FaceCheck(False, -np.inf, np.inf, 0, "too large for exact checks")
    x = solution_at_level(structure, sol.x, c)
    why = shift_multipliers(structure, x) or exact_multipliers(structure, x)
    if why:
        return FaceCheck(False, -np.inf, np.inf, 0, why)
    coef0: dict = {}
    exact_u_terms(structure, np.asarray(psatz.theta, float), x, coef0)
    coefq = {e: Fraction(v) for e, v in structure.q.terms.items()}
    pairs = gram_entries(u)
    if any(v != 0 and m not in pairs for m, v in list(coef0.items()) + list(coefq.items())):
        return FaceCheck(False, -np.inf, np.inf, 0, "the certificate has monomials outside every Gram block")
    live = facial_reduction(u, pairs, _reduction_coefficients(coef0, coefq))
    if isinstance(live, str) or sum(int(lv.sum()) * (int(lv.sum()) + 1) // 2 for lv in live) > MAX_EXACT_ENTRIES:
        return FaceCheck(False, -np.inf, np.inf, 0, live if isinstance(live, str) else "too large for exact checks")
    grams = [np.asarray(sol.grams[name], float) for name in u.block_names()]
    faces = _face_vectors(grams, live, pairs, (coef0, coefq))
    if not faces:
        return FaceCheck(False, -np.inf, np.inf, 0, "no singular face found")
    sys_ = _system(u, live, pairs, coef0, coefq, faces)
    for m in margins:
        for t in FACE_SHIFTS:
            free = _free_values(sys_, list(grams), live, faces, t * m)
            if _solve_psd(sys_, free, Fraction(float(m)), live):
                level = Fraction(float(c)) - Fraction(float(m))
                out = float(level)
                if Fraction(out) > level:
                    out = float(np.nextafter(out, -np.inf))
                return FaceCheck(True, out, float(m), len(faces),
                                 f"exact on the face of {len(faces)} structural kernel vector(s)")
    return FaceCheck(False, -np.inf, np.inf, len(faces), "no rational Gram matrix on the face is PSD")
