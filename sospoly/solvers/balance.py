"""The PSD checks of a lowered program at the scale of its indeterminates (review 39b).

A Gram matrix G of an SOS polynomial in the basis b(v) is PSD iff S G S is, for S = diag(2^(k . beta_i)) (beta_i
the exponent of b_i): S G S is the Gram matrix of the same polynomial in the variables v' = v / 2^k.  The PSD test of
:func:`sospoly.solvers.solve.check_certificate` measures lambda_min against the block's largest entry (or its data's
floor); with v = 1e6 v' in the data, a Gram matrix whose entries are 1e-24 on x^4 and O(1) on the constant passes
indefinite by 100% of its own entries on the rows of x^2, because those rows are far below the largest entry:
``max c s.t. X^4 + Y^4 + 0.5 X Y + 1 - c SOS`` with X = 1e-6 x was "optimal" at c = 1 (the minimum is 0.96875).

:func:`block_scalings` chooses k (integers, per indeterminate) that balances the data of the program's image-form
SOS constraints -- least squares on log2 |b_r| ~ mu - (beta_i + beta_j) . k over their nonzero rows r = (i, j), the
fit of :func:`sospoly.recentre` -- and returns S for every PSD block with a monomial basis (constraints and SOS
multipliers; every |k_i| below ``MIN_BALANCE_EXPONENT`` or no basis: None, nothing changes).
:func:`balanced_psd` is the extra test: S G S PSD within the margin of its own entries and of its data's scale.  It
only adds a condition (an accepted certificate passes both tests), so it can withdraw a claim, never make one.

:func:`balancing` goes further and gives :func:`sospoly.solvers.solve.solve_conic` the program itself at that scale
(:class:`Balance`: rows and columns scaled by powers of two, an exact equivalence that owns its inverse), so the
solver sees O(1) data: the example above is then solved, c = 0.96875.  Programs translated far from the origin
(coefficients that cancel) are not balanced by any such scaling: their claims are only withdrawn (``minimize``
translates exactly, :mod:`sospoly.recentre`; a hand-written program does not).
"""
from __future__ import annotations

import weakref
from dataclasses import dataclass, replace

import numpy as np
from scipy import sparse

from ..algebra.svec import smat, svec_scale, triu_pairs
from ..lowering.conic import ConicProblem

__all__ = ["MIN_BALANCE_EXPONENT", "MAX_BALANCE_EXPONENT", "MAX_BALANCE_BITS", "Balance", "balancing",
           "block_scalings", "balanced_psd", "balanced_ray"]

#: programs whose fitted |k_i| are all below this are balanced enough: checked and solved as they are (sospoly's own
#: programs are balanced before they are lowered, sospoly.scaling; a factor 2^8 per variable is 2^32 on a quartic)
MIN_BALANCE_EXPONENT = 8
#: |k_i| is capped at this (2^k beyond the float range would overflow S)
MAX_BALANCE_EXPONENT = 60


def _has_data(blk) -> bool:
    """An image-form SOS constraint block with its monomials: its rows (i, j) carry the polynomial's data."""
    return blk.source == "constraint" and blk.var_start is None and blk.basis is not None and \
        len(blk.basis) == blk.size


def _data_rows(problem: ConicProblem, blk) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(the data b on the block's rows as Gram entries -- svec's sqrt 2 taken off --, i, j of each row)."""
    n = blk.size * (blk.size + 1) // 2
    i, j = triu_pairs(blk.size)
    return problem.b[blk.row_start:blk.row_start + n] / svec_scale(blk.size), i, j


def _fit_rows(problem: ConicProblem) -> tuple[np.ndarray, np.ndarray] | None:
    """(exponents (R, n), log2 |data|) of the nonzero rows of the image-form SOS constraints."""
    E, y = [], []
    for blk in filter(_has_data, problem.psd_blocks):
        rows, i, j = _data_rows(problem, blk)
        live = (rows != 0) & np.isfinite(rows)
        if live.any():
            B = np.asarray(blk.basis, float)
            E.append(B[i[live]] + B[j[live]])
            y.append(np.log2(np.abs(rows[live])))
    if not E:
        return None
    return np.vstack(E), np.concatenate(y)


#: the last problem's scalings (a weak reference: the checks, the balancing, the ray test and the optimality rule of
#: one solve ask for the same problem's, as fastpath_cameras remembers the last cameras)
_LAST: tuple = (None, None)


def block_scalings(problem: ConicProblem) -> dict:
    """{block name: S (diagonal, a vector) or None} of the module docstring."""
    global _LAST
    ref, out = _LAST                            # (one tuple, read and replaced whole: safe across threads)
    if ref is not None and ref() is problem:
        return out
    out = _scalings(problem)
    try:
        _LAST = (weakref.ref(problem), out)
    except TypeError:                           # (an object without weak references: not remembered)
        pass
    return out


def _scalings(problem: ConicProblem) -> dict:
    blocks = getattr(problem, "psd_blocks", None) or ()        # (a problem-like object without blocks: nothing)
    out = {blk.name: None for blk in blocks}
    if not blocks:
        return out
    fit = _fit_rows(problem)
    if fit is None:
        return out
    E, y = fit
    A = np.hstack([E, -np.ones((len(E), 1))])
    try:
        k = np.linalg.lstsq(A, -y, rcond=None)[0][:-1]
    except np.linalg.LinAlgError:
        return out
    k = np.clip(np.round(k), -MAX_BALANCE_EXPONENT, MAX_BALANCE_EXPONENT)
    if not np.max(np.abs(k)) >= MIN_BALANCE_EXPONENT:
        return out
    for blk in problem.psd_blocks:
        if blk.basis is not None and blk.source in ("constraint", "multiplier") and len(blk.basis) == blk.size:
            out[blk.name] = np.ldexp(1.0, (np.asarray(blk.basis, np.int64) @ k.astype(np.int64)).clip(-1000, 1000))
    return out


def _block_data_scale(problem: ConicProblem, blk, S: np.ndarray) -> float:
    """max |b_r| S_i S_j over the block's rows (image form: its data), 0 where it has none."""
    if not _has_data(blk):
        return 0.0
    rows, i, j = _data_rows(problem, blk)
    with np.errstate(over="ignore", invalid="ignore"):
        rows = np.abs(rows) * S[i] * S[j]
    rows = rows[np.isfinite(rows)]
    return float(rows.max()) if rows.size else 0.0


def _congruent(M: np.ndarray, S: np.ndarray) -> np.ndarray | None:
    """S M S (symmetrised), None where it leaves the float range."""
    with np.errstate(over="ignore", invalid="ignore"):
        H = np.asarray(M, float) * np.outer(S, S)
    return 0.5 * (H + H.T) if np.all(np.isfinite(H)) else None


def balanced_psd(problem: ConicProblem, scalings: dict, values: dict, tol) -> tuple[bool, str]:
    """Are the Gram matrices ``values`` ({name: G}) PSD at the balanced scale: lambda_min(S G S) >= -psd_margin
    max(max |S G S|, floor), the floor min(1, the data's max |b| S_i S_j) of the block (of all the constraint blocks
    for a multiplier)?  (ok, why not.)"""
    data = {blk.name: _block_data_scale(problem, blk, scalings[blk.name]) for blk in problem.psd_blocks
            if scalings.get(blk.name) is not None}
    everywhere = max(data.values(), default=0.0)
    for blk in problem.psd_blocks:
        S, G = scalings.get(blk.name), values.get(blk.name)
        if S is None or G is None or not G.size:
            continue
        H = _congruent(G, S)
        if H is None:
            continue
        own = data.get(blk.name, 0.0) or everywhere
        floor = min(1.0, own) if own > 0 else 1.0
        lam = float(np.linalg.eigvalsh(H)[0])
        if not tol.psd_accepts(lam, float(np.max(np.abs(H))), floor):
            return False, f"Gram {blk.name}: lambda_min {lam:.3g} at the balanced scale of its monomials " \
                          f"(2^k per variable; margin {tol.psd_margin:g} * max({floor:.3g}, {np.max(np.abs(H)):.3g}))"
    return True, ""


def balanced_ray(problem: ConicProblem, v: np.ndarray, size: np.ndarray, tol) -> tuple[bool, str]:
    """The PSD cones of a ray's slack ``v`` (terms of sizes ``size``, one per row) at the balanced scale of
    :func:`block_scalings`: lambda_min(S smat(v) S) >= -psd_margin max(S smat(size) S).  (ok, why not.)"""
    scalings = block_scalings(problem)
    for blk in getattr(problem, "psd_blocks", None) or ():
        S = scalings.get(blk.name)
        if S is None:
            continue
        rows = slice(blk.row_start, blk.row_start + blk.size * (blk.size + 1) // 2)
        H, T = _congruent(smat(v[rows], blk.size), S), _congruent(np.abs(smat(size[rows], blk.size)), S)
        if H is None or T is None:
            continue
        lam = float(np.linalg.eigvalsh(H)[0])
        if not lam >= -tol.psd_margin * float(T.max()):
            return False, f"PSD cone {blk.name}: violated by {-lam:.3g} at the balanced scale of its monomials " \
                          f"(its terms {float(T.max()):.3g})"
    return True, ""


@dataclass(frozen=True)
class Balance:
    """The exact power-of-two equilibration of a lowered program at the balanced scale of its monomials: rows
    scaled by R (S_i S_j on the rows (i, j) of an SOS block, 1 elsewhere) and columns by C (1 / (S_i S_j) on the
    Gram variables of an SOS multiplier, 1 elsewhere): A' = R A C, b' = R b, q' = C q.  On a PSD block R is the
    congruence G -> S G S, so s' = R s lies in K iff s does; x = C x' and z = R z' map a solution back, with the
    same objective values (q'^T x' = q^T x, b'^T z' = b^T z).  Every factor is a power of two: exact."""
    rows: np.ndarray
    cols: np.ndarray

    def problem(self, p: ConicProblem) -> ConicProblem:
        A = (sparse.diags(self.rows) @ p.A @ sparse.diags(self.cols)).tocsc()
        return replace(p, A=A, b=p.b * self.rows, q=p.q * self.cols)

    def x(self, x):
        return None if x is None else np.asarray(x, float) * self.cols

    def z(self, z):
        return None if z is None else np.asarray(z, float) * self.rows


#: S_i S_j beyond 2^this (or below its inverse) is not used to re-solve (the factors must stay exact and finite)
MAX_BALANCE_BITS = 400


def balancing(problem: ConicProblem) -> Balance | None:
    """The :class:`Balance` of ``problem`` (None: balanced already, parametric, a kernel-form SOS block, or factors
    beyond 2^``MAX_BALANCE_BITS``)."""
    if problem.params or any(b.var_start is not None for b in problem.psd_blocks):
        return None
    scalings = block_scalings(problem)
    if all(S is None for S in scalings.values()):
        return None
    R, C = np.ones(problem.n_rows), np.ones(problem.n_cols)
    A = problem.A.tocsr()
    for blk in problem.psd_blocks:
        S = scalings.get(blk.name)
        if S is None:
            continue
        i, j = triu_pairs(blk.size)
        with np.errstate(over="ignore", under="ignore"):
            f = S[i] * S[j]
        if not (np.all(np.isfinite(f)) and np.all(np.abs(np.log2(f)) <= MAX_BALANCE_BITS)):
            return None
        rows = np.arange(blk.row_start, blk.row_start + len(f))
        R[rows] = f
        if blk.source == "multiplier":                 # s = svec(G): one column per row, scaled inversely
            for r, fr in zip(rows.tolist(), f.tolist()):
                cols = A.indices[A.indptr[r]:A.indptr[r + 1]]
                if len(cols) != 1:
                    return None
                C[cols[0]] = 1.0 / fr
    _other_columns(problem, R, C, done=C != 1.0)
    return Balance(R, C)


def _other_columns(problem: ConicProblem, R: np.ndarray, C: np.ndarray, done: np.ndarray) -> None:
    """C of the columns not set yet: 2^-m, m the median of log2 R over the column's nonzero rows (rounded).  The
    image form's parameters (each moves weight between the pairs of one monomial, rows of one R) come out exactly
    balanced; a scalar on the constant row keeps 1.  Any positive C gives the same program: this only chooses its
    conditioning."""
    A = problem.A.tocsc()
    logR = np.log2(R)
    for col in np.flatnonzero(~done).tolist():
        rows = A.indices[A.indptr[col]:A.indptr[col + 1]]
        if rows.size:
            C[col] = np.ldexp(1.0, -int(np.round(np.median(logR[rows]))))
