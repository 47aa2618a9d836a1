"""Certified 3D uncertainty of a triangulated point: ``uncertainty`` and ``uncertainty_many``.

The set (docs/uncertainty.md): ``S = {X : Phi(X, P_i) in R_i (dilated by r_i px), depth_i(X) >= 0}``,
an intersection of second-order cones and half-spaces in X~ (:mod:`.sets`).  Its box, per-view
depth intervals and largest distance from an estimate are outer bounds made rigorous from dual
multipliers (:mod:`.rigour`), each with a feasible inner witness; unbounded directions and empty
sets are reported from the solver's certificates (a ray, a Farkas dual), never from a big number.
"""
from __future__ import annotations

import enum
import logging
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike

from sospoly.solvers import BlockStatus, StackedConicOptions

from ..model.cameras import WorldFrame, depth_rows, as_world_frame, power2_scale
from ..model.geometry import validate_cameras
from ..model.regions import ConeKind, as_regions, conic_form_of
from ..solve.options import OptionError, OptionTypeError
from .angle import triangulation_angles
from .rigour import box_from_bounds, combine, lower_bounds, round_down, round_up
from .sets import EPS, dilate, structure_key, view_blocks, view_coefficients
from .solve import objective_rows, solve_blocks
from .witness import (centres, exact_rays, feasible, in_box, pull_inside, ray_point_in_set, rays_stay_inside,
                      repeat_block, witness_gap)

__all__ = ["UncertaintyStatus", "UncertaintyOptions", "UncertaintyResult", "uncertainty", "uncertainty_many"]

_LOG = logging.getLogger(__name__)


class UncertaintyStatus(str, enum.Enum):
    """What the outer bounds say about S."""
    BOUNDED = "bounded"          #: finite certified box, depth intervals and distance bound
    UNBOUNDED = "unbounded"      #: a ray of S certifies +-inf on at least one side of the box
    EMPTY = "empty"              #: a Farkas certificate says no point satisfies every view
    FAILED = "failed"            #: no certificate (reported box: the whole space)


#: dilations (pixels) are at most this (their squares stay finite) and, when positive, at least
#: DILATION_MIN (their squares stay normal numbers; a larger dilation is still an outer bound).
DILATION_MAX = 1e150
DILATION_MIN = 1e-150


@dataclass(frozen=True)
class UncertaintyOptions:
    """``dilation``: pixels added around every region (a number or one per view; 0: regions as
    given; a Point needs > 0 to have an interior); ``solver``: stack size and tolerances of
    :class:`sospoly.solvers.stacked_conic.StackedConicOptions`; ``witness_rtol``: relative slack of
    the feasibility test of witnesses in views without interior (points, segments); ``depth_bounds``:
    solve the 2N depth bound problems (True) or bound the depths over the certified box (False:
    rigorous, looser, about (6 + 2N) / 6 times faster); ``widen_roundoff``: points and segments not
    dilated by more are widened by the round-off of a computed projection (16 eps relative, see
    :func:`_roundoff_radii`), so exact data give a tiny set holding the point instead of an empty or
    degenerate one; when such a widened set yields no feasible point at all, the regions as given are
    solved too and their Farkas certificate, if any, reports the set empty; ``level_degree``: relaxation
    degree of the SOS bounds of a level set of point regions (None: the dilation relaxation only);
    ``level_time_limit``: seconds for those SOS bounds together (past it the relaxation's box is kept,
    ``definition = "level_relaxed"``; review 43a: 116 s at 40 views); ``world_frame``: the handedness in which
    "in front" (depth > 0) is judged, as :class:`tritools.TriangulationOptions` (``"reflected"`` for a mirrored
    reconstruction)."""
    dilation: float | tuple = 0.0
    solver: StackedConicOptions = field(default_factory=StackedConicOptions)
    witness_rtol: float = 1e-9
    depth_bounds: bool = True
    widen_roundoff: bool = True
    level_degree: int | None = 2
    world_frame: WorldFrame | str = WorldFrame.RIGHT_HANDED
    level_time_limit: float = 20.0

    def __post_init__(self) -> None:
        try:
            object.__setattr__(self, "world_frame", as_world_frame(self.world_frame))
        except ValueError as exc:
            raise OptionError("world_frame", f"is invalid: {exc}", str(exc)) from None
        d = self.level_degree
        if d is not None and (isinstance(d, bool) or not isinstance(d, (int, np.integer)) or d < 2 or d % 2):
            raise OptionError("level_degree", f"must be None or an even integer >= 2, got {d!r}")
        for name in ("depth_bounds", "widen_roundoff"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise OptionTypeError(name, f"must be True or False, got {getattr(self, name)!r}")
        raw = np.atleast_1d(np.asarray(self.dilation)) if not isinstance(self.dilation, (str, bool)) else None
        d = raw.astype(float) if raw is not None and raw.dtype.kind in "iuf" else None
        if d is None or d.ndim != 1 or not np.all(np.isfinite(d)) or np.any(d < 0) or np.any(d > DILATION_MAX):
            raise OptionError("dilation", f"must be a finite number in [0, {DILATION_MAX:g}] pixels or one per view, "
                                          f"got {self.dilation!r}")
        if not isinstance(self.solver, StackedConicOptions):
            raise OptionTypeError("solver", f"must be a StackedConicOptions, got {type(self.solver).__name__}")
        t = self.level_time_limit
        if isinstance(t, bool) or not isinstance(t, (int, float)) or not (t > 0 and np.isfinite(t)):
            raise OptionError("level_time_limit", f"must be a positive finite number of seconds, got {t!r}")
        if not (isinstance(self.witness_rtol, (int, float)) and 0 <= self.witness_rtol < 1):
            raise OptionError("witness_rtol", f"must be in [0, 1), got {self.witness_rtol!r}")


@dataclass(frozen=True)
class UncertaintyResult:
    """Certified outer bounds of the uncertainty set S of one point.

    ``lo``, ``hi`` (3,): world box containing S (+-inf where unbounded; +inf/-inf for an empty S);
    ``depth_lo``, ``depth_hi`` (N,): depth interval in each camera; ``max_distance``: bound on
    ``||X - estimate||`` over S, ``distance_witness`` a point of S at ``distance_inner`` from it;
    ``witness_lo``, ``witness_hi`` (3, 3): row k a point of S with ``X_k`` within ``gap`` of
    ``lo_k`` / ``hi_k`` (NaN rows where no point attains it: unbounded side, empty set);
    ``gap``: largest such distance (world units), ``gap_rel`` the same over the box's largest width
    (inf for an unbounded box with a loose finite side; :func:`.witness.witness_gap`);
    ``convexified``: an EllipseBorder was replaced by its filled ellipse (outer bound only);
    ``rigorous``: the finite bounds are certified (False only for finite sides of an unbounded S,
    which are exact to the dual residual but not certified against points beyond 1/residual);
    ``definition``: ``"per_view"``, ``"level_relaxed"`` (the outer relaxation of a level set) or
    ``"level_sos"`` (tightened by SOS bounds); ``angle_deg``: the triangulation angle at the estimate
    (largest angle between two viewing rays, :func:`tritools.triangulation_angle`).
    """
    status: UncertaintyStatus
    lo: np.ndarray
    hi: np.ndarray
    depth_lo: np.ndarray
    depth_hi: np.ndarray
    max_distance: float
    distance_inner: float
    distance_witness: np.ndarray
    estimate: np.ndarray
    witness_lo: np.ndarray
    witness_hi: np.ndarray
    gap: float
    gap_rel: float
    convexified: bool
    rigorous: bool
    definition: str = "per_view"
    angle_deg: float = float("nan")

    @property
    def bounded(self) -> bool:
        return self.status in (UncertaintyStatus.BOUNDED, UncertaintyStatus.EMPTY)

    @property
    def radius(self) -> float:
        """Alias of ``max_distance`` (the certified uncertainty radius around the estimate)."""
        return self.max_distance

    def contains(self, X) -> bool:
        """Whether X lies in the certified box (a quick necessary test for X in S)."""
        X = np.asarray(X, float)
        return bool(np.all(X >= self.lo) and np.all(X <= self.hi))


# ----------------------------------------------------------------------------- preparation
def _prepare(cameras, regions, dilation, widen=True):
    C = validate_cameras(cameras, min_views=1, require_distinct=False)
    affine = np.flatnonzero(~np.all(np.isfinite(depth_rows(C)), axis=1))
    if affine.size:
        raise ValueError(f"cameras[{int(affine[0])}] has a zero third row in its left 3x3 block (an affine camera): "
                         "its depth, and so the set S, is not defined; uncertainty needs projective cameras")
    regs = as_regions(regions, len(C))
    d = np.atleast_1d(np.asarray(dilation, float))
    if len(d) == 1:
        d = np.full(len(C), d[0])
    if len(d) != len(C):
        raise ValueError(f"dilation must be a number or have one entry per view ({len(C)}), got {len(d)}")
    forms = [conic_form_of(r) for r in regs]
    convexified = any(f.convexified for f in forms)
    thin = np.array([f.kind in (ConeKind.POINT, ConeKind.SEGMENT) for f in forms])
    if widen and thin.any():
        # a dilation below the round-off radius is raised to it too: S then grows with the dilation (a
        # dilation of 1e-100 once gave an empty set where dilation 0, widened, gave the point)
        e = np.where(thin, _roundoff_radii(C, regs), 0.0)
        thin = thin & (d < e)
        d = np.where(thin, e, d)
    widened = bool(widen and thin.any())
    d = np.where(d > 0, np.maximum(d, DILATION_MIN), 0.0)
    regs = tuple(dilate(r, float(di)) for r, di in zip(regs, d))
    return C, regs, convexified, widened


def _witnessless(res: UncertaintyResult) -> bool:
    """Not empty, yet no feasible point was found (a widened thin set the solver cannot resolve)."""
    return res.status != UncertaintyStatus.EMPTY and not np.isfinite(res.witness_lo).any() and \
        not np.isfinite(res.witness_hi).any() and not np.isfinite(res.distance_witness).any()


def _unwidened_if_empty(res, cameras, regions, estimate, opts):
    """For a widened problem without any feasible witness: the regions as given, if their set is
    certified empty (Farkas), else ``res``."""
    if not _witnessless(res):
        return res
    alt = uncertainty(cameras, regions, estimate=estimate, options=replace(opts, widen_roundoff=False))
    return alt if alt.status == UncertaintyStatus.EMPTY else res


def _roundoff_radii(C, regs) -> np.ndarray:
    """Per view, 16 times the round-off of a computed projection near the DLT point of the region
    centres, ``eps (|p1||X~| + |p2||X~| + (|x1| + |x2|) |p3||X~|) / |p3 X~|`` (pixels): points and
    segments are widened by it, so that a scene point whose *computed* projection is on the region
    belongs to S (without it, exact-looking data give an empty set in exact arithmetic)."""
    X0 = _estimates(C[None], [regs])[0]
    Xh = np.append(X0, 1.0)
    h = C @ Xh
    a = np.abs(C) @ np.abs(Xh)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        x = np.abs(h[:, :2] / h[:, 2:3]).sum(axis=1)
        e = 16 * EPS * (a[:, 0] + a[:, 1] + x * a[:, 2]) / np.abs(h[:, 2])
    scale = np.array([1.0 + float(np.max(np.abs(r.center))) for r in regs])
    return np.where(np.isfinite(e) & (e > 0), np.maximum(e, 16 * EPS * scale), 16 * EPS * scale)


def _signed(C: np.ndarray, h: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(exact signed cameras ``h sign(det M) P / 2^k`` (M, N, 3, 4), depth rows (M, N, 4)): the sign is
    read from :func:`tritools.model.cameras` depth rows (one sign rule, Hartley-Zisserman (6.15) times the
    world frame's handedness ``h``)."""
    rows = depth_rows(C) * h
    sign = np.sign(np.einsum("...j,...j->...", rows[..., :3], C[..., 2, :3]))
    sign = np.where(sign == 0, 1.0, sign)
    return C / power2_scale(C, (-2, -1)) * sign[..., None, None], rows


def _scale(R, blocks, X0, depth_rows) -> np.ndarray:
    """Normalisation length sigma (M,): the largest lateral size ``depth * radius / focal`` over views
    with a radius (a thin view -- a widened point -- must not set it), else 1e-6 of the mean depth or of
    the distance to the cameras (the solver works in (X - X0) / sigma)."""
    dep = np.abs(np.einsum("mnj,mj->mn", depth_rows[..., :3], X0) + depth_rows[..., 3])
    Xh = np.concatenate([X0, np.ones((len(X0), 1))], axis=1)
    h = np.einsum("mnij,mj->mni", R, Xh)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        J = (R[..., :2, :3] - (h[..., :2] / h[..., 2:3])[..., None] * R[..., 2:3, :3]) / h[..., 2:3, None]
    good = np.all(np.isfinite(J), axis=(2, 3))
    gain = np.zeros(good.shape)
    if np.any(good):
        gain[good] = np.linalg.norm(J[good], axis=(1, 2), ord=2)         # px per world unit
    rad = np.zeros(dep.shape)
    for i, b in enumerate(blocks):
        if b.kind == "ellipse":
            rad[:, i] = np.sqrt(np.linalg.eigvalsh(b.D)[:, -1])
        elif b.kind == "polytope":
            rad[:, i] = np.sqrt(2.0) / np.linalg.svd(b.B, compute_uv=False)[:, -1]
        elif b.kind == "segment":
            rad[:, i] = np.linalg.norm(b.d, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        lat = np.where((rad > 0) & (gain > 0), rad / gain, np.inf)
    sigma = np.where(np.isfinite(lat), lat, 0.0).max(axis=1)      # the thickest view sets the scale
    far = _scene_size(R, X0)
    fallback = 1e-6 * np.maximum(np.maximum(dep.mean(axis=1), far), 1e-300)
    sigma = np.where(np.isfinite(sigma) & (sigma > 0), sigma, fallback)
    return np.where(np.isfinite(sigma) & (sigma > 0), sigma, 1.0)


def _estimates(C, regs_stack):
    """A cheap start per problem: DLT of the region centres (the caller usually passes its own)."""
    from ..model.geometry import dlt
    out = []
    for Cm, regs in zip(C, regs_stack):
        try:
            out.append(dlt(Cm, np.array([r.center for r in regs])))
        except ValueError:
            out.append(np.zeros(3))
    return np.array(out)


# ----------------------------------------------------------------------------- certificates
def _view_slices(blocks):
    """Per view, the column ranges of its zero, nonneg and SOC rows in the stacked row order."""
    counts = [b.counts for b in blocks]
    n0 = sum(c[0] for c in counts)
    n1 = sum(c[1] for c in counts)
    out, o0, o1, o2 = [], 0, n0, n0 + n1
    for c in counts:
        out.append((slice(o0, o0 + c[0]), slice(o1, o1 + c[1]), slice(o2, o2 + 3 * c[2])))
        o0, o1, o2 = o0 + c[0], o1 + c[1], o2 + 3 * c[2]
    return out


def _inequalities(blocks, R, X0, z):
    """Certified ``a' xi + b >= 0`` (a, ae, b, be) from multipliers z (M, K, m) of every block."""
    M, K, _ = z.shape
    flat = z.reshape(M * K, -1).astype(np.longdouble)
    gam, gerr = [], []
    for blk, (s0, s1, s2) in zip(blocks, _view_slices(blocks)):
        rep = repeat_block(blk, K, np.longdouble)
        g, e = view_coefficients(rep, flat[:, s0], flat[:, s1], flat[:, s2])
        gam.append(g)
        gerr.append(e)
    gamma = np.nan_to_num(np.stack(gam, axis=1), nan=0.0)
    gerr = np.stack(gerr, axis=1)
    Rk = np.repeat(R, K, axis=0)
    return combine(gamma, gerr, Rk, np.repeat(X0, K, axis=0))


def _depth_offsets(depth_rows, X0):
    """(q0, error bound): the depth at X0, ``q . X0 + q_4`` per view (M, N)."""
    t = depth_rows[..., :3] * X0[:, None, :]
    q0 = t.sum(axis=2) + depth_rows[..., 3]
    return q0, 8 * EPS * (np.abs(t).sum(axis=2) + np.abs(depth_rows[..., 3]))


# ----------------------------------------------------------------------------- one structure group
def _group(C, regs_stack, X0, Xe, convexified, opts) -> list[UncertaintyResult]:
    return group_blocks(C, view_blocks(regs_stack), X0, Xe, convexified, opts)


#: points per call of :func:`_group_chunk` (bounds the memory of the stacked arrays)
GROUP_CHUNK = 2000


def group_blocks(C, blocks, X0, Xe, convexified, opts) -> list[UncertaintyResult]:
    """Results for M problems of one structure: cameras C (M, N, 3, 4), per-view stacked regions
    ``blocks`` (:class:`~.sets.ViewBlock`), solver centres X0 and distance references Xe (M, 3);
    processed :data:`GROUP_CHUNK` points at a time."""

    M = C.shape[0]
    conv = np.broadcast_to(np.asarray(convexified, dtype=bool), (M,))
    out = []
    for a in range(0, M, GROUP_CHUNK):
        s = slice(a, a + GROUP_CHUNK)
        part = [replace(b, **{k: (None if getattr(b, k) is None else getattr(b, k)[s])
                              for k in ("center", "D", "Dinv", "L", "B", "c", "d")}) for b in blocks]
        out.extend(_group_chunk(C[s], part, X0[s], Xe[s], conv[s], opts))
    return out


def _group_chunk(C, blocks, X0, Xe, convexified, opts) -> list[UncertaintyResult]:
    M, N = C.shape[:2]
    R, drows = _signed(C, opts.world_frame.sign)
    sigma = _scale(R, blocks, X0, drows)
    targets = objective_rows(drows)
    if not opts.depth_bounds:
        targets = targets[:, :6]
    K = targets.shape[1]
    blk = solve_blocks(R, blocks, X0, sigma, targets, opts.solver)
    a, ae, b, be = _inequalities(blocks, R, X0, blk.z)
    beta, rho, ok = lower_bounds(a, ae, b, be, targets.reshape(M * K, 3))
    beta, rho, ok = beta.reshape(M, K), rho.reshape(M, K), ok.reshape(M, K)
    st = blk.status
    solved = (st == BlockStatus.SOLVED) & ok
    ray = st == BlockStatus.UNBOUNDED
    empty = _empty(st, b.reshape(M, K), be.reshape(M, K), a.reshape(M, K, 3), ae.reshape(M, K, 3), sigma)
    # a Farkas verdict is local (it excludes the points within its reach of X0): a point found in S refutes it
    empty &= ~(feasible(blocks, R, X0, opts.witness_rtol) | feasible(blocks, R, Xe, opts.witness_rtol))
    if np.any(empty):
        empty &= ~ray_point_in_set(blocks, R, np.maximum(_scene_size(R, X0), sigma), opts.witness_rtol, empty)
        empty &= _finite_start(R, blocks, empty)
    witnesses = np.where(((st == BlockStatus.SOLVED))[:, :, None], X0[:, None, :] + sigma[:, None, None] * blk.eta,
                         np.nan)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        dirs = np.where(ray[:, :, None], blk.eta / np.linalg.norm(blk.eta, axis=2, keepdims=True), np.nan)
    centre = centres(blocks, R, witnesses[:, :6], X0, dirs, sigma, opts.witness_rtol)
    witnesses = pull_inside(blocks, R, witnesses, centre, opts.witness_rtol)
    ray &= rays_stay_inside(blocks, R, witnesses, centre, blk.eta, ray, opts.witness_rtol, targets)
    ray = exact_rays(blocks, R, blk.eta, ray, targets)     # a ray claims +-inf: a direction must recede exactly
    q0, q0e = _depth_offsets(drows, X0)
    conv = np.broadcast_to(np.asarray(convexified, dtype=bool), (M,))
    w = np.linalg.svd(R.reshape(-1, 3, 4))[2][:, -1].reshape(M, N, 4)
    with np.errstate(divide="ignore", invalid="ignore"):
        angles = triangulation_angles(w[..., :3] / w[..., 3:], Xe)
    out = []
    for m in range(M):
        out.append(_assemble(m, N, solved[m], ray[m], empty[m], beta[m], rho[m], witnesses[m], X0[m], Xe[m],
                             sigma[m], q0[m], q0e[m], bool(conv[m]), drows[m]))
    return [replace(r, angle_deg=float(a)) for r, a in zip(out, angles)]


def _finite_start(R, blocks, rows) -> np.ndarray:
    """(M,) False for the problems ``rows`` whose region centres have no finite DLT point ('at infinity': nearly
    parallel rays, whose set a Farkas ball and the ray search both miss -- review 45c H1: 0.2 px discs 0.3 px apart
    across the baseline of a stereo pair with zero disparity, a set from depth ~3000 to infinity, called empty)."""
    from ..model.geometry import dlt
    ok = np.ones(len(rows), bool)
    for m in np.flatnonzero(rows):
        try:
            dlt(R[m], np.array([b.center[m] for b in blocks]))
        except ValueError:
            ok[m] = False
    return ok


def _scene_size(R, X0) -> np.ndarray:
    """(M,) the largest distance from X0 to a finite camera centre (0 where none is)."""
    M, N = R.shape[:2]
    w = np.linalg.svd(R.reshape(-1, 3, 4))[2][:, -1].reshape(M, N, 4)
    with np.errstate(divide="ignore", invalid="ignore"):
        far = np.linalg.norm(w[..., :3] / w[..., 3:] - X0[:, None, :], axis=2)
    return np.where(np.isfinite(far), far, 0.0).max(axis=1)


def _empty(st, b, be, a, ae, sigma):
    """A problem is empty when a block's Farkas dual, turned into ``a' xi + b >= 0`` with ``b < 0``,
    excludes every point within ``1e6 sigma`` of X0 (rigorous there; beyond, to the dual's residual).  A ball is not
    space: the caller then looks for a point of S along the views' centre rays and at their pairwise closest points
    (:func:`.witness.ray_point_in_set`), where the sets a ball misses lie (nearly parallel rays; review 45b H1: the
    solver's scale fell to 1e-6 of the scene with the DLT 'at infinity', and a ball of radius 1650 was accepted for a
    set starting at depth 2000)."""
    inf = st == BlockStatus.INFEASIBLE
    reach = 1e6 * sigma[:, None]
    excl = (b + be < 0) & ((np.abs(a) + ae).sum(axis=2) * reach < -(b + be))
    return np.any(inf & excl, axis=1)


def _assemble(m, N, solved, ray, empty, beta, rho, W, X0, Xe, sigma, q0, q0e, convexified, drows
              ) -> UncertaintyResult:
    nanw = np.full((3, 3), np.nan)
    if empty:
        return UncertaintyResult(UncertaintyStatus.EMPTY, np.full(3, np.inf), np.full(3, -np.inf),
                                 np.full(N, np.inf), np.full(N, -np.inf), np.nan, np.nan, np.full(3, np.nan),
                                 Xe.copy(), nanw, nanw.copy(), 0.0, 0.0, convexified, True)
    cs, cr = solved[:6], ray[:6]
    if np.all(cs):
        lo, hi, Mx = box_from_bounds(beta[None, :3], rho[None, :3], beta[None, 3:6], rho[None, 3:6])
        lo, hi, Mx = lo[0], hi[0], float(Mx[0])
        status, rigorous = (UncertaintyStatus.BOUNDED, True) if np.isfinite(Mx) else (UncertaintyStatus.FAILED, True)
    elif np.all(cs | cr) and np.any(cr):
        status, rigorous = UncertaintyStatus.UNBOUNDED, False
        finite = W[np.all(np.isfinite(W), axis=1)]
        Mx = 10.0 * float(np.max(np.abs(finite - X0))) if len(finite) else 0.0
        lo = np.where(cs[:3], beta[:3] - rho[:3] * Mx, -np.inf)
        hi = np.where(cs[3:6], -beta[3:6] + rho[3:6] * Mx, np.inf)
    else:
        status, rigorous, Mx = UncertaintyStatus.FAILED, True, np.inf
        lo, hi = np.full(3, -np.inf), np.full(3, np.inf)
    if status == UncertaintyStatus.FAILED:
        lo, hi = np.full(3, -np.inf), np.full(3, np.inf)
    lo_w = round_down(X0 + lo)
    hi_w = round_up(X0 + hi)
    if len(solved) > 6:
        dlo, dhi = _depth_bounds(N, solved, ray, beta, rho, Mx, q0, q0e, status)
    else:
        dlo, dhi = _box_depths(lo, hi, drows, X0, q0, q0e, status)
    W = in_box(W, lo_w, hi_w)
    wl = np.where(np.isfinite(lo_w)[:, None], W[:3], np.nan)
    wh = np.where(np.isfinite(hi_w)[:, None], W[3:6], np.nan)
    gap, gap_rel, inner, dw = witness_gap(lo_w, hi_w, wl, wh, Xe, status == UncertaintyStatus.BOUNDED, W)
    far = np.maximum(np.abs(lo_w - Xe), np.abs(hi_w - Xe))
    with np.errstate(over="ignore", invalid="ignore"):
        dist = float(round_up(np.sqrt(np.sum(far * far)) * (1 + 8 * EPS))) if np.all(np.isfinite(far)) else np.inf
    if status == UncertaintyStatus.FAILED:
        wl, wh, gap, gap_rel = nanw, nanw.copy(), np.inf, np.inf
    return UncertaintyResult(status, lo_w, hi_w, dlo, dhi, dist, inner, dw, Xe.copy(), wl, wh, gap, gap_rel,
                             convexified, rigorous)


def _box_depths(lo, hi, drows, X0, q0, q0e, status):
    """Depth interval of each view over the certified box ``X0 + [lo, hi]`` (xi coordinates):
    ``q . xi + q0`` at the box's extreme corners, rounded outwards."""
    N = len(drows)
    if status != UncertaintyStatus.BOUNDED:
        return np.zeros(N), np.full(N, np.inf)
    q = drows[:, :3]
    a, b = q * lo, q * hi
    mn, mx = np.minimum(a, b).sum(axis=1), np.maximum(a, b).sum(axis=1)
    err = 8 * EPS * (np.maximum(np.abs(a), np.abs(b)).sum(axis=1) + np.abs(q0)) + q0e
    return np.maximum(round_down(mn + q0 - err), 0.0), round_up(mx + q0 + err)


def _depth_bounds(N, solved, ray, beta, rho, Mx, q0, q0e, status):
    """Depth interval per view from blocks 6 + 2i (lower) and 7 + 2i (upper); [0, inf] without them."""
    lo_i, hi_i = 6 + 2 * np.arange(N), 7 + 2 * np.arange(N)
    with np.errstate(over="ignore", invalid="ignore"):
        lo = round_down(beta[lo_i] - rho[lo_i] * Mx * (1 + 4 * EPS) + q0 - q0e)
        hi = round_up(-beta[hi_i] + rho[hi_i] * Mx * (1 + 4 * EPS) + q0 + q0e)
    lo = np.where(solved[lo_i] & np.isfinite(lo), np.maximum(lo, 0.0), 0.0)
    hi = np.where(solved[hi_i] & np.isfinite(hi), hi, np.inf)
    if status == UncertaintyStatus.FAILED:
        lo, hi = np.zeros(N), np.full(N, np.inf)
    return lo, hi


# ----------------------------------------------------------------------------- public API
def uncertainty(cameras: ArrayLike, regions: Sequence | ArrayLike, *, level: float | None = None,
                estimate: ArrayLike | None = None, options: UncertaintyOptions | None = None,
                dilation: float | ArrayLike | None = None) -> UncertaintyResult:
    """Certified outer bounds of the set S of scene points consistent with the regions.

    Parameters
    ----------
    cameras : (N, 3, 4) projection matrices.
    regions : N regions (anything :func:`tritools.as_regions` accepts).
    level : None or tau >= 0 (pixels)
        None: the per-view set (regions as given, optionally dilated).  A number: outer bounds of the
        level set ``{X : gamma(X) <= tau}`` through the per-view set of the regions dilated by
        ``sqrt(2N) tau`` (valid, up to sqrt(2N) loose; ``definition = "level_relaxed"``).
    estimate : (3,) optional
        Reference point of ``max_distance`` (e.g. the certified optimum); default the DLT of the
        region centres.
    options : UncertaintyOptions
    dilation : number or one per view, optional
        Shortcut for ``options.dilation`` (pixels added around every region).

    Returns
    -------
    UncertaintyResult
    """
    opts = _options(options, dilation)
    if level is None:
        C, regs, conv, widened = _prepare(cameras, regions, opts.dilation, opts.widen_roundoff)
        Xe = _estimate_arg(estimate, C[None], [regs])
        X0 = Xe if estimate is None else _estimates(C[None], [regs])
        res = _group(C[None], [regs], X0, Xe, conv, opts)[0]
        return _unwidened_if_empty(res, cameras, regions, estimate, opts) if widened else res
    from .level import level_bounds
    return level_bounds(cameras, regions, level, estimate, opts)


def uncertainty_many(cameras: Sequence | ArrayLike, regions: Sequence, *, estimates: Sequence | ArrayLike | None = None,
                     options: UncertaintyOptions | None = None,
                     dilation: float | ArrayLike | None = None) -> list[UncertaintyResult]:
    """:func:`uncertainty` for many points: ``cameras`` a sequence of (N_m, 3, 4) arrays (or one
    (M, N, 3, 4) array), ``regions`` a sequence of region lists, ``estimates`` (M, 3) optional.
    Problems of one structure (view count and region kinds) are solved together as stacked conic
    programs (:mod:`sospoly.solvers.stacked_conic`)."""
    opts = _options(options, dilation)
    for name, seq in (("cameras", cameras), ("regions", regions)):
        if not hasattr(seq, "__len__") or isinstance(seq, (str, bytes)):
            raise TypeError(f"{name} must be a sequence with one entry per point (a list or array), "
                            f"got {type(seq).__name__}")
    if len(cameras) != len(regions):
        raise ValueError(f"cameras and regions must have one entry per point, got {len(cameras)} and {len(regions)}")
    prepared = [_prepared_point(m, c, r, opts) for m, (c, r) in enumerate(zip(cameras, regions))]
    E = None
    if estimates is not None:
        E = _real_or_none(estimates)
        if E is None or E.shape != (len(prepared), 3) or not np.all(np.isfinite(E)):
            raise ValueError(f"estimates must be a finite ({len(prepared)}, 3) array, got "
                             f"{'shape ' + str(E.shape) if E is not None else repr(estimates)}")
    groups: dict = {}
    for m, (C, regs, _, _) in enumerate(prepared):
        groups.setdefault((len(C),) + structure_key(regs), []).append(m)
    out: list = [None] * len(prepared)
    for idx in groups.values():
        C = np.stack([prepared[m][0] for m in idx])
        regs = [prepared[m][1] for m in idx]
        X0 = _estimates(C, regs)                    # the solvers' centre: never the caller's estimate (review 26b F1)
        res = _group(C, regs, X0, X0 if E is None else E[idx], np.array([prepared[m][2] for m in idx]), opts)
        for m, r in zip(idx, res):
            out[m] = r
    for m, p in enumerate(prepared):
        if p[3]:
            out[m] = _unwidened_if_empty(out[m], cameras[m], regions[m], None if E is None else E[m], opts)
    return out


def _options(options, dilation) -> UncertaintyOptions:
    if options is None:
        options = UncertaintyOptions()
    if not isinstance(options, UncertaintyOptions):
        raise TypeError(f"options must be an UncertaintyOptions, got {type(options).__name__}")
    if dilation is not None:
        options = replace(options, dilation=dilation)        # every other option kept
    return options


def _real_or_none(a):
    """``a`` as a float array when it holds real numbers (not booleans), else None."""
    try:
        raw = np.asarray(a)
    except (TypeError, ValueError):
        return None
    return raw.astype(float) if raw.dtype.kind in "iuf" else None


def _prepared_point(m: int, cameras, regions, opts) -> tuple:
    """:func:`_prepare` of point ``m`` of :func:`uncertainty_many`; a refusal names the point."""
    try:
        return _prepare(cameras, regions, opts.dilation, opts.widen_roundoff)
    except ValueError as exc:
        try:
            named = type(exc)(f"point {m}: {exc}")
        except TypeError:                       # a subclass with its own signature
            named = ValueError(f"point {m}: {exc}")
        raise named from None


def _estimate_arg(estimate, C, regs):
    if estimate is None:
        return _estimates(C, regs)
    X = _real_or_none(estimate)
    if X is None or X.shape != (3,) or not np.all(np.isfinite(X)):
        raise ValueError(f"estimate must be a finite 3-vector, got {estimate!r}")
    return X[None]
