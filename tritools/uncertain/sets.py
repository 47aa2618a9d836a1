"""The per-view uncertainty set as conic constraints on X~ = (X, 1) (docs/uncertainty.md).

``S = {X : Phi(X, P_i) in R_i, depth_i(X) >= 0, i = 1..N}`` (the closure of the set with
depth > 0, so its bounds are the same).  With ``r_i = s_i P_i`` (``s_i = sign(det M_i)`` times a
power of two: exact, and ``r_i3 . X~`` has the sign of the depth, Hartley-Zisserman (6.15)), write
``a = (r_i1 . X~, r_i2 . X~)`` and ``s = r_i3 . X~`` so that ``Phi = a / s``.  Each region is then
a cone in X~ (all constraints are homogeneous of degree one):

=========================  ================================================  =================
region                     constraint on X~                                  cone
=========================  ================================================  =================
Point {x^}                 ``a - x^ s = 0``, ``s >= 0``                      2 zero + 1 nonneg
Segment x^ + t d, |t|<=1   ``n'(a - x^ s) = 0``, ``|d'(a - x^ s)| <= d'd s``  1 zero + 2 nonneg
Polytope ||B y + c||<=1    ``(1 -+ c_k) s -+ B_k a >= 0``                    2m nonneg
Ellipse (y-x^)'D^-1(..)<=1 ``||L'(a - x^ s)|| <= s``, ``D^-1 = L L'``         SOC(3)
EllipseBorder              its convex hull, the filled ellipse (outer bound)  SOC(3)
=========================  ================================================  =================

(``n = (-d_2, d_1)``.)  The table is each region's own
:meth:`~tritools.model.regions.Region.conic_form` (a :class:`~tritools.model.regions.ConicForm`): this
module reads the form, never the region type, so a new region type that declares its conic form gets the
certified uncertainty, and one that does not is refused with a TypeError naming ``conic_form()``; a
dilated region is :func:`tritools.model.regions.dilate` of it.  A dual multiplier of these constraints is
turned back into coefficients ``gamma_i = (g_1, g_2, g_3)`` of the exact rows ``r_i1, r_i2, r_i3`` such
that ``gamma_i . r_i X~ >= 0`` on S (:func:`view_coefficients`); for an ellipse the multiplier ``(t, u)``
gives ``g_12 = L u`` and ``t`` is raised, if needed, to a float above ``sqrt(g_12' D g_12)`` (then
``|g_12'(a - x^ s)| <= t s`` exactly).  Each coefficient carries a bound on its own round-off.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.regions import ConeKind, conic_form_of, dilate

__all__ = ["ViewBlock", "dilate", "view_blocks", "rows_of", "view_coefficients", "cone_layout", "contains"]

EPS = float(np.finfo(float).eps)


@dataclass(frozen=True)
class ViewBlock:
    """One view's region for a stack of M problems (same kind in every problem).

    ``kind`` a :class:`~tritools.model.regions.ConeKind` (its value string is accepted); ``center`` (M, 2);
    ``D`` / ``Dinv`` / ``L`` (M, 2, 2) for ellipses; ``B`` (M, m, 2), ``c`` (M, m) for polytopes; ``d`` (M, 2)
    for segments.
    """
    kind: ConeKind
    center: np.ndarray
    D: np.ndarray | None = None
    Dinv: np.ndarray | None = None
    L: np.ndarray | None = None
    B: np.ndarray | None = None
    c: np.ndarray | None = None
    d: np.ndarray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "kind", ConeKind(self.kind))

    @property
    def counts(self) -> tuple[int, int, int]:
        """(zero rows, nonneg rows, SOC(3) cones)."""
        return {ConeKind.POINT: (2, 1, 0), ConeKind.SEGMENT: (1, 2, 0), ConeKind.ELLIPSE: (0, 0, 1)}.get(
            self.kind, (0, 2 * (0 if self.B is None else self.B.shape[1]), 0))


def _eps(a) -> float:
    """Unit round-off bound of a's floating type (float64 or the platform's long double)."""
    return float(np.finfo(np.asarray(a).dtype).eps)


def structure_key(regions) -> tuple:
    """Regions of equal keys stack into one :class:`ViewBlock` per view."""
    out = []
    for r in regions:
        form = conic_form_of(r)
        out.append((form.kind, len(form.c)) if form.kind == ConeKind.POLYTOPE else (form.kind,))
    return tuple(out)


def view_blocks(regions_stack) -> list[ViewBlock]:
    """Per view, the stacked :class:`ViewBlock` of M problems' regions (all of one structure key), from their
    conic forms."""
    blocks = []
    for col in zip(*regions_stack):
        forms = [conic_form_of(r) for r in col]
        kind = forms[0].kind
        centers = np.array([f.center for f in forms])
        if kind == ConeKind.POINT:
            blocks.append(ViewBlock(kind, centers))
        elif kind == ConeKind.SEGMENT:
            blocks.append(ViewBlock(kind, centers, d=np.array([f.direction for f in forms])))
        elif kind == ConeKind.POLYTOPE:
            blocks.append(ViewBlock(kind, centers, B=np.array([f.B for f in forms]), c=np.array([f.c for f in forms])))
        else:
            Dinv = np.array([f.Dinv for f in forms])
            blocks.append(ViewBlock(kind, centers, D=np.array([f.D for f in forms]), Dinv=Dinv,
                                    L=np.linalg.cholesky(Dinv)))
    return blocks


def cone_layout(blocks) -> tuple[int, int, int]:
    """Total (zero rows, nonneg rows, SOC(3) cones) of one problem."""
    z = sum(b.counts[0] for b in blocks)
    n = sum(b.counts[1] for b in blocks)
    s = sum(b.counts[2] for b in blocks)
    return z, n, s


def rows_of(block: ViewBlock, R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Constraint rows (as linear forms on X~) of one view for M problems, R (M, 3, 4) the exact
    signed cameras: (zero rows (M, k0, 4), nonneg rows (M, k1, 4), SOC rows (M, 3k2, 4)).  Float
    rows: they go to the solver only; rigour comes from :func:`view_coefficients`."""
    M = len(R)
    a, s = R[:, :2, :], R[:, 2:3, :]
    v = a - block.center[:, :, None] * s                      # a - x^ s, (M, 2, 4)
    empty = np.zeros((M, 0, 4))
    if block.kind == ConeKind.POINT:
        return v, s, empty
    if block.kind == ConeKind.SEGMENT:
        d = block.d
        n = np.stack([-d[:, 1], d[:, 0]], axis=1)
        eq = np.einsum("mk,mkj->mj", n, v)[:, None, :]
        dd = np.sum(d * d, axis=1)[:, None]
        dv = np.einsum("mk,mkj->mj", d, v)
        return eq, np.stack([dd * s[:, 0] - dv, dd * s[:, 0] + dv], axis=1), empty
    if block.kind == ConeKind.POLYTOPE:
        Ba = np.einsum("mkl,mlj->mkj", block.B, a)             # (M, m, 4)
        cs = block.c[:, :, None] * s                          # (M, m, 4)
        lower = s - cs - Ba
        upper = s + cs + Ba
        return empty, np.concatenate([lower, upper], axis=1), empty
    Lv = np.einsum("mlk,mlj->mkj", block.L, v)                # L' v
    return empty, empty, np.concatenate([s, Lv], axis=1)


def _sum_err(terms: np.ndarray, axis: int) -> tuple[np.ndarray, np.ndarray]:
    """(float sum, bound on its round-off) of products of at most three floats summed along ``axis``."""
    n = terms.shape[axis]
    return terms.sum(axis=axis), (n + 4) * _eps(terms) * np.abs(terms).sum(axis=axis)


def view_coefficients(block: ViewBlock, z0, z1, z2) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients ``gamma`` (M, 3) on the exact rows ``r_1, r_2, r_3`` of one view, and bounds on
    their round-off (M, 3), from the dual multipliers of :func:`rows_of`'s rows (zero: free, nonneg:
    clipped at 0, SOC: made feasible), so that ``gamma . r X~ >= 0`` for every X~ of the set."""
    x = block.center
    EPS = _eps(x)
    if block.kind == ConeKind.POINT:
        nu, mu = z0, np.maximum(z1[:, 0], 0.0)
        g3, e3 = _sum_err(np.stack([mu, -nu[:, 0] * x[:, 0], -nu[:, 1] * x[:, 1]], axis=1), 1)
        return np.column_stack([nu, g3]), np.column_stack([np.zeros_like(nu), e3])
    if block.kind == ConeKind.SEGMENT:
        d = block.d
        n = np.stack([-d[:, 1], d[:, 0]], axis=1)
        nu = z0[:, 0]
        mu_lo, mu_hi = np.maximum(z1[:, 0], 0.0), np.maximum(z1[:, 1], 0.0)
        dm = mu_hi - mu_lo
        ms = mu_hi + mu_lo
        t12 = np.stack([nu[:, None] * n, dm[:, None] * d], axis=2)          # (M, 2, 2)
        g12, e12 = _sum_err(t12, 2)
        e12 = e12 + 2 * EPS * np.abs(dm)[:, None] * np.abs(d)
        t3 = np.stack([-nu * n[:, 0] * x[:, 0], -nu * n[:, 1] * x[:, 1], ms * d[:, 0] * d[:, 0],
                       ms * d[:, 1] * d[:, 1], -dm * d[:, 0] * x[:, 0], -dm * d[:, 1] * x[:, 1]], axis=1)
        g3, e3 = _sum_err(t3, 1)
        e3 = e3 + 2 * EPS * (np.abs(ms) + np.abs(dm)) * np.sum(np.abs(d) * (np.abs(d) + np.abs(x)), axis=1)
        return np.column_stack([g12, g3]), np.column_stack([e12, e3])
    if block.kind == ConeKind.POLYTOPE:
        m = block.B.shape[1]
        mu_lo, mu_hi = np.maximum(z1[:, :m], 0.0), np.maximum(z1[:, m:], 0.0)
        dm = mu_hi - mu_lo                                                   # (M, m)
        t12 = dm[:, :, None] * block.B                                       # (M, m, 2)
        g12, e12 = _sum_err(t12, 1)
        e12 = e12 + 2 * EPS * np.sum(np.abs(t12), axis=1)
        t3 = np.concatenate([mu_lo + mu_hi, dm * block.c], axis=1)
        g3, e3 = _sum_err(t3, 1)
        e3 = e3 + 2 * EPS * np.sum(np.abs(dm * block.c), axis=1)
        return np.column_stack([g12, g3]), np.column_stack([e12, e3])
    t, u = z2[:, 0], z2[:, 1:3]
    g12 = np.einsum("mkl,ml->mk", block.L, u)                  # L u, a float multiplier: exact as stored
    q = np.einsum("mk,mkl,ml->m", g12, block.D, g12)
    qa = np.einsum("mk,mkl,ml->m", np.abs(g12), np.abs(block.D), np.abs(g12))
    need = np.sqrt(np.maximum(q + 8 * EPS * qa, 0.0)) * (1 + 8 * EPS)
    t = np.maximum(t, need)
    g3, e3 = _sum_err(np.stack([t, -g12[:, 0] * x[:, 0], -g12[:, 1] * x[:, 1]], axis=1), 1)
    return np.column_stack([g12, g3]), np.column_stack([np.zeros_like(g12), e3])


def contains(block: ViewBlock, R: np.ndarray, X: np.ndarray, rtol: float = 0.0) -> np.ndarray:
    """Whether ``X`` (M, 3) lies in the view's set (projection in the region, depth >= 0) for each
    problem; ``rtol`` widens the test relative to the region's size (points and segments, which have
    no interior, need a tolerance)."""
    Xh = np.concatenate([X, np.ones((len(X), 1))], axis=1)
    h = np.einsum("mij,mj->mi", R, Xh)
    s = h[:, 2]
    ok = s > 0
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        y = h[:, :2] / np.where(ok, s, 1.0)[:, None]
    scale = 1.0 + np.max(np.abs(block.center), axis=1)
    if block.kind == ConeKind.POINT:
        return ok & (np.max(np.abs(y - block.center), axis=1) <= rtol * scale)
    if block.kind == ConeKind.SEGMENT:
        d = block.d
        dd = np.sum(d * d, axis=1)
        t = np.clip(np.einsum("mk,mk->m", y - block.center, d) / dd, -1, 1)
        return ok & (np.linalg.norm(y - block.center - t[:, None] * d, axis=1) <= rtol * scale)
    if block.kind == ConeKind.POLYTOPE:
        val = np.abs(np.einsum("mkl,ml->mk", block.B, y) + block.c)
        return ok & np.all(val <= 1.0 + rtol, axis=1)
    u = y - block.center
    return ok & (np.einsum("mk,mkl,ml->m", u, block.Dinv, u) <= 1.0 + rtol)
