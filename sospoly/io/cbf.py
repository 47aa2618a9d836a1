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
    for n, line in enumerate(path.read_text().splitlines(), start=1):
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


def _list(secs, name, path):
    """The entries of a coordinate section (its first line is the count)."""
    lines = secs.get(name, [])
    if not lines:
        return []
    count = _num(lines[0][1][0], lines[0][0], path, int)
    if count != len(lines) - 1:
        raise ValueError(f"{path}:{lines[0][0]}: {name} announces {count} entries, has {len(lines) - 1}")
    return lines[1:]


def read_cbf(path):
    """Read the CBF subset of :func:`write_cbf` into a :class:`~sospoly.lowering.conic.ConicProblem`."""
    from ..lowering.conic import Cone, ConicProblem, PSDBlockMap

    path = pathlib.Path(path)
    secs = _sections(path)
    if "VAR" not in secs:
        raise ValueError(f"{path}: no VAR section")
    var = secs["VAR"]
    n = _num(var[0][1][0], var[0][0], path, int)
    if any(toks[0] != "F" for _, toks in var[1:]):
        raise ValueError(f"{path}:{var[1][0]}: only free variables (F) are supported")
    sense = secs.get("OBJSENSE", [(0, ["MIN"])])[0][1][0]
    sign = -1.0 if sense == "MAX" else 1.0
    q = np.zeros(n)
    for ln, (j, v) in _list(secs, "OBJACOORD", path):
        q[_num(j, ln, path, int)] += sign * _num(v, ln, path)
    offset = _num(secs["OBJBCOORD"][0][1][0], secs["OBJBCOORD"][0][0], path) if "OBJBCOORD" in secs else 0.0
    con = secs.get("CON", [])
    kinds = {v: k for k, v in _CBF_CONE.items()}
    cones, m = [], 0
    for ln, (k, d) in (con[1:] if con else []):
        if k not in kinds:
            raise ValueError(f"{path}:{ln}: cone {k!r} not supported (L=, L+, Q)")
        cones.append(Cone(kinds[k], _num(d, ln, path, int)))
        m += cones[-1].dim
    psd_sizes = [_num(t[0], ln, path, int) for ln, t in secs.get("PSDCON", [])[1:]]
    psd_start = np.cumsum([m] + [s * (s + 1) // 2 for s in psd_sizes])
    nrows = int(psd_start[-1])
    rows, cols, vals, b = [], [], [], np.zeros(nrows)
    for ln, (i, j, v) in _list(secs, "ACOORD", path):
        rows.append(_num(i, ln, path, int)), cols.append(_num(j, ln, path, int)), vals.append(-_num(v, ln, path))
    for ln, (i, v) in _list(secs, "BCOORD", path):
        b[_num(i, ln, path, int)] += _num(v, ln, path)

    def svec_row(p, a, c, ln):
        a, c = _num(a, ln, path, int), _num(c, ln, path, int)
        lo, hi = min(a, c), max(a, c)
        return int(psd_start[p]) + hi * (hi + 1) // 2 + lo, (1.0 if lo == hi else np.sqrt(2.0))

    for ln, (p, j, a, c, v) in _list(secs, "HCOORD", path):
        r, sc = svec_row(_num(p, ln, path, int), a, c, ln)
        rows.append(r), cols.append(_num(j, ln, path, int)), vals.append(-_num(v, ln, path) * sc)
    for ln, (p, a, c, v) in _list(secs, "DCOORD", path):
        r, sc = svec_row(_num(p, ln, path, int), a, c, ln)
        b[r] += _num(v, ln, path) * sc
    A = sp.csc_matrix((vals, (rows, cols)), shape=(nrows, n))
    blocks = tuple(PSDBlockMap(f"psd{p}", int(psd_start[p]), s, "constraint") for p, s in enumerate(psd_sizes))
    cones += [Cone("psd", s * (s + 1) // 2, s) for s in psd_sizes]
    return ConicProblem(q, A, b, tuple(cones), n, blocks, sign, offset)
