"""Conic Benchmark Format (CBF, version 3) for :class:`~sospoly.lowering.conic.ConicProblem`.

CBF (Friberg, "CBLIB 2014") states ``min g^T x + g_0`` over free scalar variables with affine conic
constraints ``A x + b in K`` (cones ``L=``, ``L+``, ``Q``) and affine PSD constraints
``sum_j x_j H_j + D PSD`` (``PSDCON`` with ``HCOORD``/``DCOORD``, lower-triangular entries).
The lowered problem ``min q^T x, s = b - A x in K`` maps directly: scalar cones become ``CON``
rows with ``ACOORD = -A`` and ``BCOORD = b`` (``L=`` zero, ``L+`` nonnegative, ``Q`` second-order),
each PSD block a ``PSDCON`` with H_j = -mat(A[:, j]) and D = mat(b) (svec entries off the
diagonal divided by sqrt 2).  The written objective is ``objective_sign * q^T x + objective_offset``
under ``OBJSENSE MAX`` when ``objective_sign`` is -1, so the file states the caller's problem.
:func:`read_cbf` reads this subset back (``VAR`` of free variables only).
"""
from __future__ import annotations

import pathlib

import numpy as np
import scipy.sparse as sp

from ..algebra.svec import svec_scale, triu_pairs

__all__ = ["write_cbf", "read_cbf"]

_CBF_CONE = {"zero": "L=", "nonneg": "L+", "soc": "Q"}
_KEYWORDS = {"VER", "OBJSENSE", "VAR", "INT", "PSDVAR", "PSDCON", "CON", "OBJFCOORD", "OBJACOORD", "OBJBCOORD",
             "FCOORD", "ACOORD", "BCOORD", "HCOORD", "DCOORD"}


def write_cbf(problem, path) -> pathlib.Path:
    """Write ``problem`` (without parameters) as a CBF file (module docstring)."""
    if problem.params:
        raise ValueError("write_cbf: instantiate the problem's parameters first (ConicProblem.instantiate)")
    path = pathlib.Path(path)
    A = sp.csr_matrix(problem.A)
    scalar_cones, psd, row = [], [], 0
    con_rows = []                                   # problem rows in CBF CON order
    for cone in problem.cones:
        if cone.kind == "psd":
            psd.append((row, cone.size))
        else:
            scalar_cones.append((_CBF_CONE[cone.kind], cone.dim))
            con_rows += range(row, row + cone.dim)
        row += cone.dim
    sign = problem.objective_sign
    out = ["# written by sospoly (ConicProblem.to_cbf)", "VER", "3", "", "OBJSENSE", "MAX" if sign < 0 else "MIN", "",
           "VAR", f"{problem.n_cols} 1", f"F {problem.n_cols}", ""]
    if psd:
        out += ["PSDCON", str(len(psd))] + [str(s) for _, s in psd] + [""]
    if scalar_cones:
        out += ["CON", f"{len(con_rows)} {len(scalar_cones)}"] + [f"{k} {d}" for k, d in scalar_cones] + [""]
    qn = np.nonzero(problem.q)[0]
    out += ["OBJACOORD", str(qn.size)] + [f"{j} {float(sign * problem.q[j])!r}" for j in qn] + [""]
    if problem.objective_offset:
        out += ["OBJBCOORD", repr(float(problem.objective_offset)), ""]
    acoord, bcoord, hcoord, dcoord = [], [], [], []
    for k, r in enumerate(con_rows):
        lo, hi = A.indptr[r], A.indptr[r + 1]
        acoord += [f"{k} {c} {float(-v)!r}" for c, v in zip(A.indices[lo:hi], A.data[lo:hi]) if v != 0.0]
        if problem.b[r] != 0.0:
            bcoord.append(f"{k} {float(problem.b[r])!r}")
    for p, (start, size) in enumerate(psd):
        i, j = triu_pairs(size)
        for t, (a, b_, sc) in enumerate(zip(i, j, svec_scale(size))):
            r = start + t
            lo, hi = A.indptr[r], A.indptr[r + 1]        # lower triangle: (row, col) = (j, i) with j >= i
            hcoord += [f"{p} {c} {b_} {a} {float(-v / sc)!r}"
                       for c, v in zip(A.indices[lo:hi], A.data[lo:hi]) if v != 0.0]
            if problem.b[r] != 0.0:
                dcoord.append(f"{p} {b_} {a} {float(problem.b[r] / sc)!r}")
    for name, items in (("ACOORD", acoord), ("BCOORD", bcoord), ("HCOORD", hcoord), ("DCOORD", dcoord)):
        if items:
            out += [name, str(len(items))] + items + [""]
    path.write_text("\n".join(out) + "\n")
    return path


def _sections(path: pathlib.Path) -> dict:
    """Keyword -> list of (line number, data line) following it."""
    secs, cur = {}, None
    try:
        text = path.read_text()
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not a text (UTF-8) file: {exc.reason} at byte {exc.start}") from None
    for n, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        if s in _KEYWORDS:
            if s in secs:
                raise ValueError(f"{path}:{n}: section {s} repeated")
            cur = secs.setdefault(s, [])
            continue
        if cur is None:
            raise ValueError(f"{path}:{n}: data before the first keyword: {s!r}")
        cur.append((n, s.split()))
    return secs


def _num(tok, n, path, conv=float):
    try:
        return conv(tok)
    except ValueError:
        raise ValueError(f"{path}:{n}: expected {'an integer' if conv is int else 'a number'}, got {tok!r}") from None


#: largest count or dimension a file may declare (a larger one is refused by file:line before anything is
#: allocated: a corrupt header must not ask for terabytes)
MAX_DIM = 10**7


def _index(tok, n, path, size: int, what: str) -> int:
    """An integer token in ``[0, size)`` (ValueError naming file:line otherwise)."""
    v = _num(tok, n, path, int)
    if not 0 <= v < size:
        raise ValueError(f"{path}:{n}: {what} {v} out of range [0, {size})")
    return v


def _dim(tok, n, path, what: str, low: int = 0) -> int:
    """A declared count or dimension in ``[low, MAX_DIM]``."""
    v = _num(tok, n, path, int)
    if not low <= v <= MAX_DIM:
        raise ValueError(f"{path}:{n}: {what} {v} out of range [{low}, {MAX_DIM}]")
    return v


def _list(secs, name, path, arity: int | None = None):
    """The entries of a coordinate section (its first line is the count), each of ``arity`` tokens."""
    lines = secs.get(name, [])
    if not lines:
        return []
    count = _num(lines[0][1][0], lines[0][0], path, int)
    if count != len(lines) - 1:
        raise ValueError(f"{path}:{lines[0][0]}: {name} announces {count} entries, has {len(lines) - 1}")
    for ln, toks in lines[1:]:
        if arity is not None and len(toks) != arity:
            raise ValueError(f"{path}:{ln}: a {name} entry has {arity} fields, got {len(toks)}")
    return lines[1:]


def _header(secs, name, path, arity: int = 1):
    """The first line of section ``name`` (ValueError naming the file when it is missing or short)."""
    lines = secs.get(name)
    if not lines:
        raise ValueError(f"{path}: section {name} has no data")
    ln, toks = lines[0]
    if len(toks) < arity:
        raise ValueError(f"{path}:{ln}: {name} needs {arity} fields, got {len(toks)}")
    return ln, toks


def read_cbf(path):
    """Read the CBF subset of :func:`write_cbf` into a :class:`~sospoly.lowering.conic.ConicProblem`."""
    from ..lowering.conic import Cone, ConicProblem, PSDBlockMap

    path = pathlib.Path(path)
    secs = _sections(path)
    if "VAR" not in secs:
        raise ValueError(f"{path}: no VAR section")
    var = secs["VAR"]
    ln0, toks0 = _header(secs, "VAR", path, 2)
    n = _dim(toks0[0], ln0, path, "VAR count")
    if any(toks[0] != "F" for _, toks in var[1:]):
        raise ValueError(f"{path}:{var[1][0]}: only free variables (F) are supported")
    sense = "MIN"
    if "OBJSENSE" in secs:        # (the CBF keywords MIN and MAX; anything else is refused, not read as MIN)
        ln, toks = _header(secs, "OBJSENSE", path)
        sense = toks[0].upper()
        if sense not in ("MIN", "MAX") or len(toks) != 1:
            raise ValueError(f"{path}:{ln}: OBJSENSE must be MIN or MAX, got {' '.join(toks)!r}")
    sign = -1.0 if sense == "MAX" else 1.0
    q = np.zeros(n)
    for ln, (j, v) in _list(secs, "OBJACOORD", path, 2):
        q[_index(j, ln, path, n, "variable")] += sign * _num(v, ln, path)
    offset = _num(_header(secs, "OBJBCOORD", path)[1][0], secs["OBJBCOORD"][0][0], path) \
        if "OBJBCOORD" in secs else 0.0
    con = secs.get("CON", [])
    kinds = {v: k for k, v in _CBF_CONE.items()}
    cones, m = [], 0
    for ln, toks in (con[1:] if con else []):
        if len(toks) != 2:
            raise ValueError(f"{path}:{ln}: a CON entry has 2 fields (cone, dimension), got {len(toks)}")
        k, d = toks
        if k not in kinds:
            raise ValueError(f"{path}:{ln}: cone {k!r} not supported (L=, L+, Q)")
        cones.append(Cone(kinds[k], _dim(d, ln, path, "cone dimension", 1)))
        m += cones[-1].dim
    if con:
        ln, toks = _header(secs, "CON", path, 2)
        if (_num(toks[0], ln, path, int), _num(toks[1], ln, path, int)) != (m, len(cones)):
            raise ValueError(f"{path}:{ln}: CON announces total dimension {toks[0]} in {toks[1]} cones, has "
                             f"{m} in {len(cones)}")
    psd = secs.get("PSDCON", [])
    if psd and _num(_header(secs, "PSDCON", path)[1][0], psd[0][0], path, int) != len(psd) - 1:
        raise ValueError(f"{path}:{psd[0][0]}: PSDCON announces {psd[0][1][0]} blocks, has {len(psd) - 1}")
    psd_sizes = [_dim(t[0], ln, path, "PSDCON side", 1) for ln, t in psd[1:]]
    psd_start = np.cumsum([m] + [s * (s + 1) // 2 for s in psd_sizes])
    nrows = int(psd_start[-1])
    if nrows > MAX_DIM:
        raise ValueError(f"{path}: the cones declare {nrows} rows, more than MAX_DIM = {MAX_DIM}")
    rows, cols, vals, b = [], [], [], np.zeros(nrows)
    for ln, (i, j, v) in _list(secs, "ACOORD", path, 3):
        rows.append(_index(i, ln, path, m, "row")), cols.append(_index(j, ln, path, n, "variable"))
        vals.append(-_num(v, ln, path))
    for ln, (i, v) in _list(secs, "BCOORD", path, 2):
        b[_index(i, ln, path, m, "row")] += _num(v, ln, path)

    def svec_row(p, a, c, ln):
        side = psd_sizes[p]
        a, c = _index(a, ln, path, side, "PSD entry index"), _index(c, ln, path, side, "PSD entry index")
        lo, hi = min(a, c), max(a, c)
        return int(psd_start[p]) + hi * (hi + 1) // 2 + lo, (1.0 if lo == hi else np.sqrt(2.0))

    for ln, (p, j, a, c, v) in _list(secs, "HCOORD", path, 5):
        r, sc = svec_row(_index(p, ln, path, len(psd_sizes), "PSD block"), a, c, ln)
        rows.append(r), cols.append(_index(j, ln, path, n, "variable")), vals.append(-_num(v, ln, path) * sc)
    for ln, (p, a, c, v) in _list(secs, "DCOORD", path, 4):
        r, sc = svec_row(_index(p, ln, path, len(psd_sizes), "PSD block"), a, c, ln)
        b[r] += _num(v, ln, path) * sc
    A = sp.csc_matrix((vals, (rows, cols)), shape=(nrows, n))
    blocks = tuple(PSDBlockMap(f"psd{p}", int(psd_start[p]), s, "constraint") for p, s in enumerate(psd_sizes))
    cones += [Cone("psd", s * (s + 1) // 2, s) for s in psd_sizes]
    return ConicProblem(q, A, b, tuple(cones), n, blocks, sign, offset)
