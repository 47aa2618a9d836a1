"""Data normalisation that keeps the L2 problem the same (SPEC §9).

Image side: view i is translated by its region centre t_i and **all** views are scaled by one
common factor s, x' = s (x - t_i).  A common isotropic scale multiplies every distance by s, so
gamma' = s gamma and the minimiser is unchanged (a per-view scale would re-weight the views and
change the problem).  The scale makes the unknowns O(1) at the optimum: s = 1 / rho with rho the RMS
residual of a *locally refined* L2 estimate of the region centres (the linear (DLT) estimate, then
Levenberg-Marquardt on the reprojection residuals), an approximation of gamma* from above.  Then
c = 2N gamma'^2 is O(1), the scale at which the certificate tolerances of
:class:`sospoly.Tolerances` are meaningful.

The regions' offset: the auxiliary points y_i of a region whose centre is not one of its points (an ellipse
border) are at least ``Region.center_offset`` from the shift t_i, whatever the residual, so s is at most one over
the largest offset (:func:`normalization_for`).  Without it, a border of radius 3.8 px around consistent centres
(rho at its floor, 0.008 px) put every border point ~470 units from the origin: the delta = 4 program's equality
multipliers then nearly cancel the level c (coefficients 1 against 5e-6), and Clarabel ended every attempt of its
retry chain in a numerical error (30 s, gamma_LB = 0; with the offset: certified in 4 s).

The floor: noise-free data have rho = 0, so rho is floored at ``RHO_FLOOR_REL`` times the views'
median *pixel scale* (:func:`tritools.model.stacked.pixel_scales`: pixels per radian, the focal
length of a finite camera) -- a property of the cameras, not of the coordinates' magnitude, so a
principal point at 1e6 px does not inflate it (a floor relative to |x| made c ~ 1e-11 there and the
certificate tolerances meaningless).  With the floor at 1e-5 f, the gap tolerance of a noise-free
problem corresponds to ~1e-8 f px.

Why the refined residual and not the DLT residual: with noisy cameras the DLT residual can exceed
gamma* by two orders of magnitude; the unknowns are then ~1e-2 at the optimum, the fixed multiplier
q = (1 + ||v||^2)^(delta/2 - 1) is ~1 there and the delta = 4 relaxation loses most of its strength
(measured on Example 5).

The resolution: the certificate rule (``sospoly.Tolerances.certified``) compares c_LB and c_UB with a
tolerance that has an absolute part (for gamma* = 0: the solver's error in c is absolute) and a relative
one.  In pixels the absolute part allows a gap of ~sqrt(tol / 2N) / s, small whenever s is the scale of
the residuals -- but not when s could not be estimated (clipped to ``SCALE_BOUNDS``: points 1e10 px off-axis of
unit-focal cameras gave c ~ 1e-10 for a 460 px residual, "certified" against gamma_LB = 0).  So a gap
that passes only through the absolute part (not ``Tolerances.certified_relatively``) must also be at most
``resolution`` in gamma:
``RESOLUTION_REL`` max(f_px, median |x|) pixels (sqrt(eps) of the coordinates' magnitude, the resolution of
a least-squares optimum in floating point), stored in normalised units (times s).  The floor f_px =
``PIXEL_FLOOR_REL`` times the views' median focal length (:func:`pixel_floors`; 1 px at f = 1000 px) stands in
for coordinates at 0 and keeps every decision invariant under a rescaling of the images.

World side: X = X0 + d X' with X0 the DLT estimate and d the median distance to the camera centres
(an affine change of the 3D frame leaves reprojections unchanged).  Cameras become
P_i' = T_i P_i H, each scaled to unit Frobenius norm.

:func:`normalization_stack` computes all of this for a stack of problems with numpy;
:func:`normalization_for` is that function applied to a stack of one (the regions' centres as the
points), so the single-point and the batched paths normalise by the same rule (a stack of one refines
with the scalar twin :func:`tritools.model.stacked.refine_point`: equal up to round-off).
"""
from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import dataclass

import numpy as np

from .exact import homogeneous_images
from .cameras import power2_scale
from .magnitude import (PIXEL_FLOOR_REL, RESOLUTION_REL, SCALAR_MAX_VIEWS, frame_magnitude_one,
                        list_median as _median, magnitudes, median_pixel_scales, origin_magnitudes, pixel_floors,
                        resolution_pair, resolution_pair_one, resolutions, world_origin_magnitude_one,
                        world_origin_magnitudes)
from .frame_floats import (centre_distances, centre_distances_array, pixel_scale_one, residual_squares,
                           residual_squares_array)
from .geometry import COMMON_CENTRE_RTOL, POINT_AT_INFINITY_RTOL, point_from_image_points
from .lm_one import FLOAT_MAX_VIEWS
from .stacked import (dlt_stack, median_rows, norms, null_vectors, pixel_scales, project_one, project_quiet,
                      project_stack, refine_point, refine_points_stack)

__all__ = ["Normalization", "NormalizationStack", "normalization_for", "normalization_stack", "regions_offset",
           "unconstrained_reason", "data_magnitude", "resolutions", "magnitudes", "origin_magnitudes",
           "world_origin_magnitudes",
           "median_pixel_scales", "pixel_floors",
           "RHO_FLOOR_REL", "RESOLUTION_REL", "PIXEL_FLOOR_REL", "DEPTH_FLOOR_REL",
           "SCALE_BOUNDS", "power_of_two_below"]

#: floor of the residual scale rho, relative to the median pixel scale (focal length) of the views.
RHO_FLOOR_REL = 1e-5
#: floor of the world scale d, relative to max(1, |X0|) (the DLT point).
DEPTH_FLOOR_REL = 1e-3
#: the common image scale s is clipped to this range.
SCALE_BOUNDS = (1e-8, 1e8)


@dataclass(frozen=True)
class Normalization:
    """The normalisation of one problem: x' = scale (x - shifts[i]), X = origin + depth X'; ``resolution`` the
    coordinates' resolution in normalised units that the decision lets a gap pass within (module docstring; inf: not
    known, no guard; :func:`~tritools.model.magnitude.guard_resolutions`), ``floor_resolution`` the median rule's
    (:func:`~tritools.model.magnitude.resolutions`) whose magnitude floors the lowering of gamma_LB (None: the
    resolution)."""
    scale: float
    shifts: np.ndarray      # (N, 2)
    origin: np.ndarray      # (3,)
    depth: float
    resolution: float = np.inf
    points_magnitude: float | None = None      # magnitudes() of the caller's points; None: from ``shifts``
    #: (num (N,), the moved cameras' third rows (N, 4), their origin c0 (3,), |depth| at X0 (N,)): the frame origin's
    #: term num_i / |P_3 X~| of :func:`origin_magnitudes`, where the frame's builder knows it
    frame_terms: tuple | None = None
    floor_resolution: float | None = None

    @property
    def lowering_resolution(self) -> float:
        """The resolution whose magnitude floors the lowering of gamma_LB (:func:`tritools.solve.decide.gamma_lower`):
        ``floor_resolution``, else ``resolution``."""
        return self.resolution if self.floor_resolution is None else self.floor_resolution

    @classmethod
    def identity(cls, n_views: int, points=None, cameras=None) -> Normalization:
        """No change of frame; the resolution of ``points`` (N, 2) with the pixel floor of ``cameras`` (1 px
        without them), none without points."""
        if points is None:
            return cls(1.0, np.zeros((n_views, 2)), np.zeros(3), 1.0)
        x = np.asarray(points, float)[None]
        res, floor_res = (float(r[0]) for r in resolution_pair(np.ones(1), x, None if cameras is None else
                                                                np.asarray(cameras, float)[None]))
        return cls(1.0, np.zeros((n_views, 2)), np.zeros(3), 1.0, res, float(magnitudes(x)[0]),
                   floor_resolution=floor_res)

    @property
    def magnitude(self) -> float:
        """max |x_i| of the caller's points in pixels (the shifts are the points): the magnitude whose round-off every
        distance carries (:func:`tritools.solve.decide.gamma_lower`, which floors it by the resolution's magnitude)."""
        if self.points_magnitude is not None:
            return self.points_magnitude
        return float(magnitudes(np.asarray(self.shifts, float)[None])[0])

    def magnitude_at(self, cameras: np.ndarray, X: np.ndarray) -> float:
        """:attr:`magnitude` and at least the estimate's: :meth:`NormalizationStack.magnitudes_at` of one problem
        (``cameras`` (N, 3, 4) the normalisation was made of, X (3,) in their frame)."""
        return max(self.magnitude, world_origin_magnitude_one(cameras, self.shifts, X, self.origin, entries=True))

    def transform(self, i: int) -> np.ndarray:
        s, (tx, ty) = self.scale, self.shifts[i]
        return np.array([[s, 0.0, -s * tx], [0.0, s, -s * ty], [0.0, 0.0, 1.0]])

    def world(self) -> np.ndarray:
        H = np.eye(4)
        H[:3, :3] *= self.depth
        H[:3, 3] = self.origin
        return H

    def cameras(self, cameras: np.ndarray) -> np.ndarray:
        """T_i P_i H / ||.||_F, the last column of P_i H (P_i (origin, 1)) compensated where it cancels as in the
        stacked normalisation (:func:`_frames`): a plain product lost ~log10(|P| |o~| / |P o~|) digits there, 1e-11
        relative next to a camera centre, beyond the round-off the lowering of gamma_LB assumes (review 46a)."""
        C = np.asarray(cameras, float)
        C = C / power2_scale(C, (1, 2))                  # exact, projectively the same: nothing below overflows
        CH = framed(C, np.asarray(self.origin, float), self.depth)
        out = np.array([self.transform(i) @ M for i, M in enumerate(CH)])
        with np.errstate(over="ignore", invalid="ignore"):
            out = out / power2_scale(out, (1, 2))
            return out / np.linalg.norm(out, axis=(1, 2))[:, None, None]

    def regions(self, regions) -> list:
        """Each region under its view's similarity; the regions of one class with a stacked construction
        (``similarity_many``: N ellipses in a few numpy calls, the same numbers) in one call per class, mixed
        lists included."""
        out = [None] * len(regions)
        by_class: dict = {}
        for i, r in enumerate(regions):
            by_class.setdefault(type(r), []).append(i)
        for cls, idx in by_class.items():
            many = getattr(cls, "similarity_many", None)
            if many is not None and len(idx) > 1:
                for i, r in zip(idx, many([regions[i] for i in idx], self.scale, self.shifts[idx])):
                    out[i] = r
            else:
                for i in idx:
                    out[i] = regions[i].similarity(self.scale, self.shifts[i])
        return out

    def world_point(self, Xn: np.ndarray) -> np.ndarray:
        return self.origin + self.depth * np.asarray(Xn, float)

    def normalized_point(self, X: np.ndarray) -> np.ndarray:
        return (np.asarray(X, float) - self.origin) / self.depth

    def image_points(self, xn: np.ndarray) -> np.ndarray:
        return self.shifts + np.asarray(xn, float) / self.scale


@dataclass(frozen=True)
class NormalizationStack:
    """The normalisations of M problems (arrays with a leading problem axis); ``ok`` False where the data
    could not be normalised (DLT at infinity, a camera centre at infinity, overflow); ``Xn`` the locally
    refined estimate in the normalised frame (0, the DLT point, where the refinement failed)."""
    scale: np.ndarray       # (M,)
    shifts: np.ndarray      # (M, N, 2)
    origin: np.ndarray      # (M, 3)
    depth: np.ndarray       # (M,)
    cameras_n: np.ndarray   # (M, N, 3, 4) normalised cameras, unit Frobenius norm each
    Xn: np.ndarray          # (M, 3)
    ok: np.ndarray          # (M,)
    resolution: np.ndarray  # (M,) the coordinates' resolution in normalised units (:class:`Normalization`)
    #: (M,) Xn is a converged local L2 minimiser (the step rule of the refinement; the image rescaling after it is
    #: a similarity, which keeps the minimiser): polishing it again is a no-op
    converged: np.ndarray | None = None
    floor_resolution: np.ndarray | None = None      # (M,) the median rule's (:class:`Normalization`)

    @property
    def lowering_resolution(self) -> np.ndarray:
        """(M,) :attr:`Normalization.lowering_resolution` of each problem."""
        return self.resolution if self.floor_resolution is None else self.floor_resolution

    def item(self, m: int) -> Normalization:
        mag = float(self.magnitudes_of(slice(m, m + 1))[0])
        return Normalization(float(self.scale[m]), self.shifts[m].copy(), self.origin[m].copy(), float(self.depth[m]),
                             float(self.resolution[m]), mag, floor_resolution=float(self.lowering_resolution[m]))

    def world_points(self, Xn: np.ndarray) -> np.ndarray:
        return self.origin + self.depth[:, None] * Xn

    @property
    def magnitude(self) -> np.ndarray:
        """(M,) max_i |x_i| sec theta_i of each problem's points (the shifts), the obliquities from the
        normalised cameras at their origin (:func:`magnitudes`), and at least the frame's origin magnitude
        (:func:`origin_magnitudes`): :attr:`Normalization.magnitude`."""
        return self.magnitudes_of(slice(None))

    def magnitudes_at(self, C: np.ndarray, X: np.ndarray) -> np.ndarray:
        """(M,) :attr:`magnitude` and at least the estimate's (:func:`world_origin_magnitudes` of the cameras C
        (M, N, 3, 4) the normalisation was made of, at the world points X (M, 3) in C's frame): what gamma_LB is
        lowered by at the reported estimate."""
        o = self.origin
        if len(X) == 1:                         # one problem: the scalar twin, the stack's numbers (any N)
            K = world_origin_magnitude_one(C[0], self.shifts[0], X[0], o[0], entries=True)
            return np.maximum(self.magnitude, K)
        return np.maximum(self.magnitude, world_origin_magnitudes(C, self.shifts, X, o, entries=True))

    def magnitudes_of(self, rows) -> np.ndarray:
        """:attr:`magnitude` of the problems ``rows`` (a slice)."""
        x, Cn = self.shifts[rows], self.cameras_n[rows]
        o = -self.origin[rows] / self.depth[rows, None]          # the given frame's origin, in the normalised one
        if len(x) == 1 and x.shape[1] <= SCALAR_MAX_VIEWS:      # one problem: the scalar twin, the same numbers
            return np.array([frame_magnitude_one(Cn[0], x[0], o[0], self.scale[rows][0])])
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            frame = origin_magnitudes(Cn, x, o, self.scale[rows])
        return np.maximum(magnitudes(x, Cn, np.zeros(x.shape)), np.where(np.isnan(frame), 1.0, frame))


def _rho_floor(med: np.ndarray, x: np.ndarray) -> np.ndarray:
    """RHO_FLOOR_REL * median pixel scale per problem (``med``, :func:`median_pixel_scales`; fallback: 1e-4 max(1,
    median |x|) where no view has a finite pixel scale)."""
    good = np.isfinite(med) & (med > 0)
    if good.all():                  # (the fallback would not be used)
        return RHO_FLOOR_REL * med
    fallback = 1e-4 * np.maximum(1.0, median_rows(np.abs(x.reshape(len(x), -1))))
    return np.where(good, RHO_FLOOR_REL * med, fallback)


#: the last stack of one normalised, (key, NormalizationStack): a single call whose stages normalise the same data
#: twice (the vectorised disc verification, then the report) computes it once.  Replaced, never mutated (a reader
#: sees the old or the new pair); hits are returned as copies, so no caller can change what another one gets.
_LAST_SINGLE: list = [None]


def normalization_stack(C: np.ndarray, x: np.ndarray, ok: np.ndarray | None = None, *,
                        scalar: bool | None = None) -> NormalizationStack:
    """The normalisation of the module docstring for M problems: cameras C (M, N, 3, 4), points x (M, N, 2)
    (the regions' centres).  A stack of one is remembered (``_LAST_SINGLE``): the function is deterministic, so
    the same data give a copy of the same arrays.  ``scalar``: a stack of one runs the scalar twin
    :func:`_normalization_one` where its data are on the common path (equal to the stacked code up to round-off,
    tests/test_scalar_twins.py); None (default): exactly when M = 1."""
    M = x.shape[0]
    ok = np.ones(M, bool) if ok is None else ok.copy()
    if M != 1:
        return _normalization_stack(C, x, ok)
    key = (C.dtype.str, C.shape, C.tobytes(), x.dtype.str, x.shape, x.tobytes(), ok.tobytes(), scalar is False)
    last = _LAST_SINGLE[0]
    if last is not None and last[0] == key:
        return _copied(last[1])
    st = _normalization_one(C[0], x, ok) if scalar is not False else None
    st = _normalization_stack(C, x, ok) if st is None else st
    _LAST_SINGLE[0] = (key, _copied(st))
    return st


def _copied(st: NormalizationStack) -> NormalizationStack:
    return NormalizationStack(*(None if a is None else a.copy() for a in
                                (st.scale, st.shifts, st.origin, st.depth, st.cameras_n, st.Xn, st.ok, st.resolution,
                                 st.converged, st.floor_resolution)))


def _normalization_stack(C: np.ndarray, x: np.ndarray, ok: np.ndarray) -> NormalizationStack:
    """:func:`normalization_stack` computed (``ok`` a copy the function may change)."""
    M, N = x.shape[:2]
    C = C / power2_scale(C, (2, 3))     # each camera by a power of two near its largest entry: exact, projectively
    X0, ok_dlt = dlt_stack(C, x)        # the same camera, and no product below overflows (cameras x 1e300)
    ok &= ok_dlt
    med = median_pixel_scales(C, x)
    rho_floor = _rho_floor(med, x)
    with np.errstate(over="ignore", invalid="ignore"):
        s, rho, X0, d, Cn = _frames(C, x, X0, ok, rho_floor)
    ok &= np.isfinite(Cn).all(axis=(1, 2, 3))
    Cn = np.where(ok[:, None, None, None], Cn, np.eye(3, 4))
    # the scale from the residual of the locally refined estimate: refine from the DLT point (Xn = 0), then
    # the exact image similarity x' -> k x', k = s_new / s
    Xn, ok_r, converged = refine_points_stack(Cn, np.zeros((M, N, 2)), np.zeros((M, 3)), ok.copy(),
                                              return_converged=True, scalar=False)    # (any M: the stack's numbers)
    u, _, fin = project_stack(Cn, Xn)
    r = np.sqrt(np.add.reduce(np.add.reduce(np.where(fin[:, None, None], u, 0.0) ** 2, axis=2), axis=1) / N) / s
    use = ok_r & fin & np.isfinite(r)
    rho_ref = np.where(use, np.maximum(np.minimum(r, rho), rho_floor), rho)
    s_new = _clip_scale(1.0 / rho_ref)
    Cn[:, :, :2, :] *= (s_new / s)[:, None, None, None]
    Cn /= norms(Cn, axis=(2, 3))[..., None, None]
    res, floor_res = resolution_pair(s_new, x, C, pixel_floors(medians=med))
    return NormalizationStack(s_new, x.copy(), X0, d, Cn, np.where(use[:, None], Xn, 0.0), ok, res, use & converged,
                              floor_res)


def _normalization_one(C: np.ndarray, x: np.ndarray, ok: np.ndarray) -> NormalizationStack | None:
    """The scalar (M = 1) twin of :func:`_normalization_stack` for cameras C (N, 3, 4) and points x (1, N, 2): the
    same steps on plain (N, ...) arrays and floats -- DLT (eigenvector of A^T A), the rho floor from the median pixel
    scale, the DLT residual rho, the world frame (X0, d = median distance to the centres, floored), the normalised
    cameras, the refinement (:func:`tritools.model.stacked.refine_point`) and the rescaling by its residual -- so
    equal to the stacked code up to round-off.  None where the data leave the common path (``ok`` False, the DLT
    point or a camera centre at infinity, no finite pixel scale, all centres shared, a projection at
    round-off, non-finite numbers): the caller runs the stacked code there, with its exact numbers."""
    if not ok[0]:
        return None
    xi = x[0]
    N = len(xi)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        P = C / power2_scale(C, (1, 2))
        X0, ok_dlt = dlt_stack(P[None], x)          # (the stacked DLT: its bits, the frame's origin)
        if not ok_dlt[0]:
            return None
        X0 = X0[0]
        frame = _frame_one(P, xi, X0)
        if frame is None:
            return None
        s, rho, rho_floor, d, Cn, med, ps_all = frame
        Xn, ok_r, converged = refine_point(Cn, np.zeros((N, 2)), np.zeros(3), True)
        u, _, fin = project_one(Cn, Xn)
        r = math.sqrt(float(np.add.reduce(np.add.reduce(u * u, axis=1))) / N) / s if fin else math.nan
        use = ok_r and fin and math.isfinite(r)
        s_new = float(_clip_scale(1.0 / (max(min(r, rho), rho_floor) if use else rho)))
        Cn[:, :2, :] *= s_new / s
        Cn /= norms(Cn, axis=(1, 2))[:, None, None]
    s_arr = np.array([s_new])
    res, floor_res = resolution_pair_one(s_new, x[0].tolist(), ps_all, med)
    return NormalizationStack(s_arr, x.copy(), X0[None], np.array([d]), Cn[None], (Xn if use else np.zeros(3))[None],
                              np.ones(1, bool), res, np.array([use and converged]), floor_res)


def _frame_one(P: np.ndarray, xi: np.ndarray, X0: np.ndarray) -> tuple | None:
    """(s, rho, rho_floor, d, Cn, median pixel scale, every view's pixel scale) of :func:`_frames`,
    :func:`_rho_floor` and :func:`median_pixel_scales` for one problem (cameras P (N, 3, 4) scaled by powers of two,
    points xi (N, 2), the DLT point X0), or None off the common path (:func:`_normalization_one`)."""
    N = len(xi)
    few = N <= FLOAT_MAX_VIEWS                           # the pieces on floats (tritools.model.frame_floats)
    Pl, xl, Xl = (P.tolist(), xi.tolist(), X0.tolist()) if few else (None, None, None)
    ps_all = [pixel_scale_one(p, q) for p, q in zip(Pl, xl)] if few else pixel_scales(P, xi).tolist()
    ps = [p for p in ps_all if 0.0 < p < math.inf]
    if not ps:
        return None
    med = _median(ps)
    rho_floor = RHO_FLOOR_REL * med
    sq = residual_squares(Pl, Xl, xl) if few else residual_squares_array(P, X0, xi)
    if sq is None or not rho_floor > 0:
        return None
    rho = max(math.sqrt(sq / N), rho_floor)
    s = float(_clip_scale(1.0 / rho))
    dist = centre_distances(Pl, Xl) if few else centre_distances_array(P, X0)
    if dist is None:
        return None
    d = _median(dist)
    d = max(d, DEPTH_FLOOR_REL * max(1.0, math.sqrt(float(X0 @ X0)))) if d > 0 else 1.0
    CH = framed(P, X0, d)
    Cn = CH.copy()
    Cn[:, :2, :] = s * (CH[:, :2, :] - xi[..., None] * CH[:, 2:3, :])
    Cn /= norms(Cn, axis=(1, 2))[:, None, None]
    if not np.isfinite(Cn).all():
        return None
    return s, rho, rho_floor, d, Cn, med, ps_all


def framed(C: np.ndarray, X0: np.ndarray, d) -> np.ndarray:
    """P H of cameras C (..., N, 3, 4) for H = [[d I, X0], [0, 1]] (X0 (..., 3), d broadcast against C): the last
    column P (X0, 1) compensated where it cancels (:func:`tritools.model.exact.homogeneous_images`: an exact change
    of frame to one rounding; a plain product lost 11 digits next to a camera centre, review 46a), the others scaled
    once.  The one frame of :func:`_frames`, :func:`_frame_one` and :meth:`Normalization.cameras`."""
    CH = C.copy()
    CH[..., :3] *= d
    CH[..., 3] = homogeneous_images(C, np.concatenate([X0, np.ones(X0.shape[:-1] + (1,))], axis=-1))
    return CH


def _clip_scale(s: np.ndarray) -> np.ndarray:
    """``np.clip(s, *SCALE_BOUNDS)`` as the two ufuncs it is made of (max, then min; NaN stays NaN), without
    clip's per-call overhead."""
    return np.minimum(np.maximum(s, SCALE_BOUNDS[0]), SCALE_BOUNDS[1])


def _frames(C: np.ndarray, x: np.ndarray, X0: np.ndarray, ok: np.ndarray, rho_floor: np.ndarray) -> tuple:
    """(s, rho, X0, d, Cn) of :func:`normalization_stack` from the DLT points X0 (``ok`` updated in place): the
    image scale s = 1 / rho from the DLT residual, the world frame (origin X0, scale d) and the normalised cameras
    P_i' = T_i P_i H / ||.||_F.  Run under ``np.errstate(over="ignore", invalid="ignore")``."""
    M, N = x.shape[:2]
    u0, _, fin0 = project_quiet(C, X0)                  # (already under errstate)
    res = np.where(fin0[:, None], norms(u0 - x, axis=2), np.inf)
    rho = np.where(fin0, np.sqrt(np.add.reduce(np.where(fin0[:, None], res, 0.0) ** 2, axis=1) / N), 1.0)
    rho = np.maximum(rho, rho_floor)
    s = _clip_scale(1.0 / rho)
    a = null_vectors(C)
    a = a / norms(a, axis=2, keepdims=True)
    affine = ~(np.abs(a[..., 3]) > POINT_AT_INFINITY_RTOL)
    ok &= ~affine.any(axis=1)
    centres = a[..., :3] / np.where(affine, 1.0, a[..., 3])[..., None]
    X0 = _off_a_common_centre(C, x, a, X0, ok)
    d = median_rows(norms(centres - X0[:, None], axis=2))
    # floored relative to |X0| (any d > 0 is an exact change of frame): when every view has one centre, the
    # DLT point *is* that centre and d ~ 1e-15 would map every normalised point onto it
    d = np.where(np.isfinite(d) & (d > 0), np.maximum(d, DEPTH_FLOOR_REL * np.maximum(1.0, norms(X0, axis=1))), 1.0)
    # P_i' = T_i P_i H / ||.||_F with T_i = [[s, 0, -s t_i], [0, s, -s t_i'], [0, 0, 1]], H = [[d I, X0], [0, 1]]
    CH = framed(C, X0, d[:, None, None, None])
    Cn = CH.copy()
    Cn[:, :, :2, :] = s[:, None, None, None] * (CH[:, :, :2, :] - x[..., None] * CH[:, :, 2:3, :])
    Cn /= norms(Cn, axis=(2, 3))[..., None, None]
    return s, rho, X0, d, Cn


def _off_a_common_centre(C: np.ndarray, x: np.ndarray, a: np.ndarray, X0: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """X0 with the problems whose views all share one centre (a: the cameras' null vectors) moved off it: there
    the DLT point *is* the centre, which makes the normalised frame degenerate (the frame's origin at the
    centre leaves the normalised cameras' last column at round-off).  They get the point of the common ray
    of the observations (:func:`tritools.model.geometry.point_from_image_points`) instead."""
    if C.shape[1] < 2:
        return X0
    scale = np.einsum("mnij,mj->mni", np.abs(C), np.abs(a[:, 0]))
    resid = np.abs(np.einsum("mnij,mj->mni", C, a[:, 0]))
    # (run under the caller's errstate; ufunc reductions, not their numpy wrappers: the same numbers)
    within = resid <= COMMON_CENTRE_RTOL * np.maximum.reduce(scale, axis=2, keepdims=True)
    shared = ok & np.logical_and.reduce(within.reshape(len(C), 3 * C.shape[1]), axis=1)
    if not shared.any():
        return X0
    X0 = X0.copy()
    for m in np.nonzero(shared)[0]:
        X = point_from_image_points(x[m], C[m])
        if X is not None:
            X0[m] = X
    return X0


def normalization_for(cameras: np.ndarray, regions, enabled: bool = True) -> Normalization:
    """The normalisation of one problem: :func:`normalization_stack` on a stack of one, with the regions'
    centres as the points (identity when ``enabled`` is False; the centres as shifts with unit scale when
    the data cannot be normalised, e.g. the DLT estimate is at infinity); the image scale then at most one over
    the regions' offset (:func:`regions_offset`, module docstring)."""
    N = len(regions)
    centers = np.array([r.center for r in regions], float)
    if not enabled:
        mag = float(magnitudes(centers[None], np.asarray(cameras, float)[None])[0])
        return dataclasses.replace(Normalization.identity(N, centers, cameras), points_magnitude=mag)
    st = normalization_stack(np.asarray(cameras, float)[None], centers[None])
    if st.ok[0]:
        norm = st.item(0)
    else:
        res, floor_res = (float(r[0]) for r in resolution_pair(np.ones(1), centers[None],
                                                                np.asarray(cameras, float)[None]))
        norm = Normalization(1.0, centers, np.zeros(3), 1.0, res,
                             float(magnitudes(centers[None], np.asarray(cameras, float)[None])[0]),
                             floor_resolution=floor_res)
    offset = regions_offset(regions)
    s = norm.scale
    if offset * s > 1.0:
        s = float(_clip_scale(np.array([1.0 / offset]))[0])
    if any(getattr(r, "exact_scale", False) for r in regions):
        s = power_of_two_below(s)
    if s != norm.scale:
        res, floor_res = (float(r[0]) for r in resolution_pair(np.array([s]), centers[None],
                                                                np.asarray(cameras, float)[None]))
        norm = dataclasses.replace(norm, scale=s, resolution=res, floor_resolution=floor_res)
    return norm


def power_of_two_below(s: float) -> float:
    """The largest power of two <= s (s > 0 finite; s itself otherwise), within ``SCALE_BOUNDS`` (doubled once where
    it falls below them).  The image scale of a problem with a region whose shape the similarity's rounding would
    change (``Region.exact_scale``: a thin ellipse, whose s^2 D rounded moves the border by ~eps lam_max / lam_min of
    the minor axis -- review 43c LOW-1: the lower bound of the moved ellipse exceeded the caller's optimum): with a
    power of two, s^2 D, s times a distance and gamma' = s gamma carry no round-off.  Only there: a power of two
    moves c = 2N gamma'^2 by up to a factor 4 from the residual's scale, and the SDPs' conditioning with it (one
    stalled Theorem 1 delta = 6 program took 24 s instead of 1 s when every problem was rounded)."""
    if not (math.isfinite(s) and s > 0):
        return s
    p = math.ldexp(1.0, math.frexp(s)[1] - 1)
    return p if p >= SCALE_BOUNDS[0] else 2.0 * p


def regions_offset(regions) -> float:
    """The largest ``Region.center_offset`` (pixels) over the regions, 0 without one.  An offset that is not a real
    number raises a TypeError naming it; one that is not finite or negative, or a region whose own arithmetic fails
    at its centre (ArithmeticError, ValueError), gives no offset: the residual rule alone, as before the offset
    existed (and never a different value for a different order of the views)."""
    out = 0.0
    for i, r in enumerate(regions):
        try:
            v = r.center_offset
        except (ArithmeticError, ValueError, np.linalg.LinAlgError):
            continue
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (numbers.Real, np.floating, np.integer)):
            raise TypeError(f"regions[{i}].center_offset must be a real number, got {type(v).__name__}")
        v = float(v)
        if math.isfinite(v) and v > out:
            out = v
    return out


#: image coordinates up to this magnitude are not blamed when the normalised pairs are lost
#: (:func:`unconstrained_reason`): the centres' separation is (review 8b: 300 px data with centres 1e-11 apart).
ORDINARY_IMAGE_DATA = 1e12


def data_magnitude(regions) -> float:
    """The largest |coordinate| of the regions' centres (pixels; NaN without regions): the size of the image data
    that messages about unrepresentable data quote."""
    centers = np.array([r.center for r in regions], float)
    with np.errstate(all="ignore"):
        return float(np.max(np.abs(centers))) if centers.size else float("nan")


#: centres closer than this relative to their distance from the origin (~4,500 ulps) are said to coincide to round-off
ROUND_OFF_BASELINE = 1e-12


def _centre_spread(cameras: np.ndarray) -> tuple[float, float]:
    """(largest distance of a centre from the first, largest distance from the world origin) of the cameras'
    centres C = -M^-1 p4 (inf: a centre at infinity), for the message of :func:`unconstrained_reason` (review 34a M2:
    centres 7.8e-4 apart at 8.6e6 were said to coincide to round-off)."""
    with np.errstate(all="ignore"):
        try:
            c = -np.linalg.solve(cameras[:, :, :3], cameras[:, :, 3:])[..., 0]
        except np.linalg.LinAlgError:
            return math.inf, math.inf
        return float(np.max(np.linalg.norm(c - c[0], axis=1))), float(np.max(np.linalg.norm(c, axis=1)))


def unconstrained_reason(cameras: np.ndarray, regions) -> tuple:
    """(status value, message) for a problem whose normalised data leave no view pair that constrains the point.

    Either the camera centres really coincide (``ill_posed``), or the pairs were lost in floating point: image
    coordinates so far from the cameras' image scale (points at 1e20 px and more) that the normalised cameras
    are numerically rank-deficient (``numerical_failure``, and the message says so instead of blaming the
    cameras), or -- with ordinary image data (|x| <= ``ORDINARY_IMAGE_DATA``) -- centres so close to each other
    that the normalised cameras cannot resolve them (``numerical_failure``, and the message names the centres)."""
    from .geometry import fundamental_matrices

    C = np.asarray(cameras, float)
    with np.errstate(all="ignore"):
        C = C / power2_scale(C, (1, 2))
        try:
            pairs = fundamental_matrices(C, skip_coincident=True)
        except ValueError:
            pairs = {}
    if not pairs:
        from .exact import same_exact_centre

        raw = np.asarray(cameras, float)
        if all(same_exact_centre(raw[0], P) for P in raw[1:]):
            return "ill_posed", ("all camera centres coincide: no view pair constrains the point (its depth is "
                                 "undetermined)")
        spread, far = _centre_spread(raw)
        how = "coincide to round-off but not exactly" if not spread > ROUND_OFF_BASELINE * far else \
            "are distinct but too close for their baseline to be resolved"
        where = f"about {spread:.2g} apart at {far:.3g} from the world origin" if math.isfinite(spread + far) else \
            "some at infinity"
        return "ill_posed", (f"the camera centres {how} ({where}): no view pair constrains the point, and next to "
                             f"the centres "
                             f"the exact problem sees that baseline, so no one-centre bound is valid (give the views "
                             f"one exact centre, e.g. the world origin at it, to have them certified as a rotation "
                             f"rig; or move the world origin near the cameras)")
    big = data_magnitude(regions)
    if big <= ORDINARY_IMAGE_DATA:
        return "numerical_failure", (f"no view pair constrains the point after normalisation although the cameras' "
                                     f"centres are distinct: they are too close to each other (a baseline near the "
                                     f"data's round-off) for the normalised cameras to resolve them (|x| up to "
                                     f"{big:.3g} px is ordinary image data)")
    return "numerical_failure", (f"the image data (|x| up to {big:.3g}) are too large for the cameras' image scale "
                                 f"to be represented in floating point: no view pair constrains the point after "
                                 f"normalisation (the cameras' centres are distinct)")
