"""SDPA sparse format (``.dat-s``) for :class:`~sospoly.lowering.conic.ConicProblem`.

SDPA's problem (Fujisawa et al., "SDPA-format")::

    minimise  c^T x    subject to  X = sum_i F_i x_i - F_0  PSD   (x free, X block diagonal)

File: comment lines (``"`` or ``*``), m, the number of blocks, the block sizes (negative: a
diagonal LP block), c, then one line ``matno block i j value`` per upper-triangular entry
(1-based; matno 0 is F_0).

Writing ``min q^T x, s = b - A x in K`` (:mod:`sospoly.lowering.conic`): X is the slack s, so
F_0 = -mat(b) and F_i = -mat(A[:, i]), c = q, and the cones become blocks:

* zero-cone rows: two LP entries each, s_r >= 0 and -s_r >= 0 (SDPA has no equality block);
* nonnegative rows: LP entries;
* a second-order cone (t, y) of dimension k: the k x k arrow matrix [[t, y^T], [y, t I]] PSD
  (PSD iff t >= ||y||);
* a PSD block in svec: its matrix (off-diagonal svec entries divided by sqrt 2).

The minimised value is q^T x; the caller's objective ``objective_sign * q^T x + objective_offset``
goes in a comment line ``"sospoly objective_sign=... objective_offset=...`` that
:func:`read_sdpa` reads back.  Reading: LP entries come back as nonnegative rows, except pairs of
entries whose data are exact negatives of each other (as written above for zero rows), which
become zero-cone rows; every SDP block becomes a PSD cone (an arrow block stays a PSD block: the
same feasible set).  So ``read_sdpa(write_sdpa(P))`` has P's optimum.
"""
from __future__ import annotations

import math
import pathlib
import re

import numpy as np
import scipy.sparse as sp

from ..algebra.svec import svec_scale, triu_pairs
from .cbf import MAX_DIM

__all__ = ["write_sdpa", "read_sdpa"]

_MARK = re.compile(r"sospoly objective_sign=(\S+) objective_offset=(\S+)")


def _entries_of_cones(problem):
    """Per row of the conic data: (block index, i, j, factor) placements (0-based i <= j), and the block
    sizes in SDPA's convention (LP block first, negative)."""
    lp_rows, lp_sign = [], []
    blocks, place = [], []            # place: (row, block, i, j, factor)
    row = 0
    for cone in problem.cones:
        rows = np.arange(row, row + cone.dim)
        if cone.kind == "zero":
            lp_rows += list(rows) + list(rows)
            lp_sign += [1.0] * cone.dim + [-1.0] * cone.dim
        elif cone.kind == "nonneg":
            lp_rows += list(rows)
            lp_sign += [1.0] * cone.dim
        elif cone.kind == "soc":
            k = len(blocks)
            blocks.append(cone.dim)
            for d in range(cone.dim):           # t on the whole diagonal
                place.append((row, k, d, d, 1.0))
            for e in range(1, cone.dim):         # y_e on the first row
                place.append((row + e, k, 0, e, 1.0))
        else:
            k = len(blocks)
            blocks.append(cone.size)
            i, j = triu_pairs(cone.size)
            for t, (a, b_, sc) in enumerate(zip(i, j, svec_scale(cone.size))):
                place.append((row + t, k, int(a), int(b_), 1.0 / sc))
        row += cone.dim
    has_lp = bool(lp_rows)
    off = 1 if has_lp else 0
    place = [(r, k + off, i, j, f) for r, k, i, j, f in place]
    place += [(r, 0, d, d, s) for d, (r, s) in enumerate(zip(lp_rows, lp_sign))]
    sizes = ([-len(lp_rows)] if has_lp else []) + blocks
    return place, sizes


def write_sdpa(problem, path) -> pathlib.Path:
    """Write ``problem`` (a ConicProblem without parameters) as an SDPA sparse file (module docstring)."""
    if problem.params:
        raise ValueError("write_sdpa: instantiate the problem's parameters first (ConicProblem.instantiate)")
    path = pathlib.Path(path)
    place, sizes = _entries_of_cones(problem)
    A = sp.csr_matrix(problem.A)
    lines = ['"written by sospoly (ConicProblem.to_sdpa): min c^T x s.t. sum_i F_i x_i - F_0 PSD',
             f'"sospoly objective_sign={float(problem.objective_sign)!r} '
             f'objective_offset={float(problem.objective_offset)!r}',
             str(problem.n_cols), str(len(sizes)), " ".join(map(str, sizes)),
             " ".join(repr(float(v)) for v in problem.q)]
    for r, k, i, j, f in place:
        if problem.b[r] != 0.0:
            lines.append(f"0 {k + 1} {i + 1} {j + 1} {float(-problem.b[r] * f)!r}")   # F_0 = -mat(b)
        lo, hi = A.indptr[r], A.indptr[r + 1]
        for col, val in zip(A.indices[lo:hi], A.data[lo:hi]):
            if val != 0.0:
                lines.append(f"{col + 1} {k + 1} {i + 1} {j + 1} {float(-val * f)!r}")     # F_i = -mat(A[:, i])
    path.write_text("\n".join(lines) + "\n")
    return path


def _header_and_lines(text: str, path=""):
    """(header tokens with line numbers, data lines with line numbers, sign, offset): comments skipped;
    header lines (m, block count, block sizes, c) cut at their first non-number (``=mDIM``...)."""
    sign, offset = 1.0, 0.0
    lines = []
    for n, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if not s or s[0] in '"*':
            m = _MARK.search(s)
            if m:
                sign = _number(m.group(1), n, float, path, "objective_sign")        # (NaN / inf: ValueError, review
                offset = _number(m.group(2), n, float, path, "objective_offset")    # 39b: a NaN objective "optimal")
            continue
        lines.append((n, [t for t in re.split(r"[\s,{}()]+", s) if t]))
    return lines, sign, offset


def _header(lines, path):
    """m, block sizes, c and the index of the first entry line."""
    toks, k = [], 0

    def need(count, conv, what):
        nonlocal k
        while len(toks) < count and k < len(lines):
            n, line = lines[k]
            k += 1
            for tok in line:
                try:
                    float(tok)
                except ValueError:
                    break
                toks.append((tok, n))
        if len(toks) < count:
            raise ValueError(f"{path}: truncated SDPA file: expected {what}")
        got = [_number(tok, n, conv, path, what) for tok, n in toks[:count]]
        del toks[:count]
        return got

    (m,) = need(1, int, "the number of variables m")
    (nb,) = need(1, int, "the number of blocks")
    if m < 0 or nb < 0 or m > MAX_DIM or nb > MAX_DIM:
        raise ValueError(f"{path}: m and the number of blocks must be in [0, {MAX_DIM}], got {m}, {nb}")
    sizes = need(nb, int, "the block sizes")
    rows = sum(abs(s) * (abs(s) + 1) // 2 if s > 0 else -s for s in sizes)
    if any(s == 0 for s in sizes) or rows > MAX_DIM:
        raise ValueError(f"{path}: block sizes must be non-zero and declare at most {MAX_DIM} rows, got {sizes} "
                         f"({rows} rows)")
    c = need(m, float, "the objective vector c")
    return m, sizes, c, k


def _number(tok, n, conv, path, what):
    try:
        v = conv(tok)
    except ValueError:
        raise ValueError(f"{path}:{n}: {what} must be {'an integer' if conv is int else 'a number'}, "
                         f"got {tok!r}") from None
    if conv is float and not math.isfinite(v):
        raise ValueError(f"{path}:{n}: {what} is not finite: {tok!r}")
    return v


def _entries(lines, sizes, m, path) -> dict:
    """(block, i, j) -> {matno: value} of the entry lines ``matno block i j value`` (0-based, i <= j)."""
    nb = len(sizes)
    entries = {}
    for n, toks in lines:
        if len(toks) < 5:
            raise ValueError(f"{path}:{n}: an entry line needs 'matno block i j value', got {' '.join(toks)!r}")
        mat, blk, i, j = (_number(t, n, int, path, "matno block i j") for t in toks[:4])
        val = _number(toks[4], n, float, path, "the entry value")
        if not (0 <= mat <= m and 1 <= blk <= nb):
            raise ValueError(f"{path}:{n}: matno {mat} or block {blk} out of range (m={m}, {nb} blocks)")
        side = abs(sizes[blk - 1])
        i, j = min(i, j), max(i, j)
        if not (1 <= i <= side and j <= side) or (sizes[blk - 1] < 0 and i != j):
            raise ValueError(f"{path}:{n}: entry ({i}, {j}) outside block {blk} of size {sizes[blk - 1]}")
        d = entries.setdefault((blk - 1, i - 1, j - 1), {})
        d[mat] = d.get(mat, 0.0) + val
    return entries


def read_sdpa(path):
    """Read an SDPA sparse file into a :class:`~sospoly.lowering.conic.ConicProblem` (module docstring)."""
    from ..lowering.conic import Cone, ConicProblem, PSDBlockMap

    path = pathlib.Path(path)
    lines, sign, offset = _header_and_lines(path.read_text(), path)
    m, sizes, c, first = _header(lines, path)
    entries = _entries(lines[first:], sizes, m, path)
    # rows: zero pairs, then LP, then PSD blocks
    zero_rows, lp_rows, psd = [], [], []
    for k, size in enumerate(sizes):
        if size < 0:
            z, l_ = _pair_lp([entries.get((k, d, d), {}) for d in range(-size)])
            zero_rows += z
            lp_rows += l_
        else:
            psd.append((k, size))
    rows_A, rows_b = [], []

    def add(data, factor):
        """One row s = b - A x of the SDPA slack X = sum F_i x_i - F_0 (times ``factor``)."""
        rows_b.append(-data.get(0, 0.0) * factor)
        rows_A.append({mt - 1: -v * factor for mt, v in data.items() if mt > 0})

    for data in zero_rows + lp_rows:
        add(data, 1.0)
    cones = ([Cone("zero", len(zero_rows))] if zero_rows else []) + ([Cone("nonneg", len(lp_rows))] if lp_rows else [])
    blocks = []
    for k, size in psd:
        blocks.append(PSDBlockMap(f"block{k + 1}", len(rows_b), size, "constraint"))
        i, j = triu_pairs(size)
        for a, b_, sc in zip(i, j, svec_scale(size)):
            add(entries.get((k, int(a), int(b_)), {}), float(sc))
        cones.append(Cone("psd", len(i), size))
    r = np.concatenate([np.full(len(d), t) for t, d in enumerate(rows_A)]) if rows_A else np.zeros(0)
    cols = np.concatenate([list(d.keys()) for d in rows_A]) if rows_A else np.zeros(0)
    vals = np.concatenate([list(d.values()) for d in rows_A]) if rows_A else np.zeros(0)
    A = sp.csc_matrix((vals, (r.astype(np.int64), cols.astype(np.int64))), shape=(len(rows_b), m))
    return ConicProblem(np.asarray(c, float), A, np.asarray(rows_b, float), tuple(cones), m, tuple(blocks),
                        sign, offset)


def _pair_lp(diag: list) -> tuple[list, list]:
    """Split LP entries into zero rows (a pair of entries with exactly negated data: s >= 0 and -s >= 0) and
    the remaining nonnegative rows."""
    key = [tuple(sorted(d.items())) for d in diag]
    neg = {}
    for t, kk in enumerate(key):
        neg.setdefault(kk, []).append(t)
    used, zero, lp = set(), [], []
    for t, kk in enumerate(key):
        if t in used:
            continue
        partners = [u for u in neg.get(tuple((mt, -v) for mt, v in kk), []) if u not in used and u != t]
        if kk and partners:
            used.update((t, partners[0]))
            zero.append(diag[t])
        else:
            used.add(t)
            lp.append(diag[t])
    return zero, lp
