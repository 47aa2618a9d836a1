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
multipliers; k = 0 or no basis: None, the test is unchanged).  :func:`balanced_psd` is the extra test: S G S PSD
within the margin of its own entries and of its data's scale.  It only adds a condition (an accepted certificate
passes both tests), so it can withdraw a claim, never make one.
"""
from __future__ import annotations

import numpy as np

from ..algebra.svec import smat, svec_scale, triu_pairs
from ..lowering.conic import ConicProblem

__all__ = ["MAX_BALANCE_EXPONENT", "block_scalings", "balanced_psd", "balanced_ray"]

#: |k_i| is capped at this (2^k beyond the float range would overflow S)
MAX_BALANCE_EXPONENT = 60


def _fit_rows(problem: ConicProblem) -> tuple[np.ndarray, np.ndarray] | None:
    """(exponents (R, n), log2 |data|) of the nonzero rows of the image-form SOS constraints."""
    E, y = [], []
    for blk in problem.psd_blocks:
        basis = getattr(blk, "basis", None)
        if basis is None or blk.source != "constraint" or blk.var_start is not None or len(basis) != blk.size:
            continue
        n = blk.size * (blk.size + 1) // 2
        rows = problem.b[blk.row_start:blk.row_start + n] / svec_scale(blk.size)
        i, j = triu_pairs(blk.size)
        live = (rows != 0) & np.isfinite(rows)
        if live.any():
            B = np.asarray(basis, float)
            E.append(B[i[live]] + B[j[live]])
            y.append(np.log2(np.abs(rows[live])))
    if not E:
        return None
    return np.vstack(E), np.concatenate(y)


def block_scalings(problem: ConicProblem) -> dict:
    """{block name: S (diagonal, a vector) or None} of the module docstring."""
    out = {blk.name: None for blk in problem.psd_blocks}
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
    if not np.any(k):
        return out
    for blk in problem.psd_blocks:
        basis = getattr(blk, "basis", None)
        if basis is not None and blk.source in ("constraint", "multiplier") and len(basis) == blk.size:
            out[blk.name] = np.ldexp(1.0, (np.asarray(basis, np.int64) @ k.astype(np.int64)).clip(-1000, 1000))
    return out


def _block_data_scale(problem: ConicProblem, blk, S: np.ndarray) -> float:
    """max |b_r| S_i S_j over the block's rows (image form: its data), 0 where it has none."""
    if blk.var_start is not None or blk.source != "constraint":
        return 0.0
    n = blk.size * (blk.size + 1) // 2
    i, j = triu_pairs(blk.size)
    with np.errstate(over="ignore", invalid="ignore"):
        rows = np.abs(problem.b[blk.row_start:blk.row_start + n] / svec_scale(blk.size)) * S[i] * S[j]
    rows = rows[np.isfinite(rows)]
    return float(rows.max()) if rows.size else 0.0


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
        with np.errstate(over="ignore", invalid="ignore"):
            H = np.asarray(G, float) * np.outer(S, S)
        if not np.all(np.isfinite(H)):
            continue
        own = data.get(blk.name, 0.0) or everywhere
        floor = min(1.0, own) if own > 0 else 1.0
        lam = float(np.linalg.eigvalsh(0.5 * (H + H.T))[0])
        if not tol.psd_accepts(lam, float(np.max(np.abs(H))), floor):
            return False, f"Gram {blk.name}: lambda_min {lam:.3g} at the balanced scale of its monomials " \
                          f"(2^k per variable; margin {tol.psd_margin:g} * max({floor:.3g}, {np.max(np.abs(H)):.3g}))"
    return True, ""


def balanced_ray(problem: ConicProblem, v: np.ndarray, size: np.ndarray, tol) -> tuple[bool, str]:
    """The PSD cones of a ray's slack ``v`` (terms of sizes ``size``, one per row) at the balanced scale of
    :func:`block_scalings`: lambda_min(S smat(v) S) >= -psd_margin max(S smat(size) S).  (ok, why not.)"""
    scalings = block_scalings(problem)
    for blk in problem.psd_blocks:
        S = scalings.get(blk.name)
        if S is None:
            continue
        rows = slice(blk.row_start, blk.row_start + blk.size * (blk.size + 1) // 2)
        W = np.outer(S, S)
        with np.errstate(over="ignore", invalid="ignore"):
            H, T = smat(v[rows], blk.size) * W, np.abs(smat(size[rows], blk.size)) * W
        if not (np.all(np.isfinite(H)) and np.all(np.isfinite(T))):
            continue
        lam = float(np.linalg.eigvalsh(0.5 * (H + H.T))[0])
        if not lam >= -tol.psd_margin * float(T.max()):
            return False, f"PSD cone {blk.name}: violated by {-lam:.3g} at the balanced scale of its monomials " \
                          f"(its terms {float(T.max()):.3g})"
    return True, ""
