"""Lens models of COLMAP beyond the OPENCV family: forward maps on normalised coordinates, a generic
Newton inverse, and pycolmap for the models without own code.

Every perspective COLMAP model maps a camera-frame point ``(x, y, z)``, ``z > 0``, to pixels as
``(px, py) = (fx u_d + cx, fy v_d + cy)`` with ``(u_d, v_d) = D(u, v)``, ``(u, v) = (x / z, y / z)``.
The maps ``D`` with own code here (COLMAP's ``src/colmap/sensor/models.h``; each is tested against
``pycolmap.Camera.img_from_cam`` in tests/test_camera_models.py):

* FULL_OPENCV ``k1..k6, p1, p2``: ``radial = (1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6)``,
  ``u_d = u radial + 2 p1 u v + p2 (r^2 + 2 u^2)``, ``v_d = v radial + 2 p2 u v + p1 (r^2 + 2 v^2)``;
* the equidistant fisheye family, ``theta = atan(r)``, ``(u_d, v_d) = (theta_d / r) (u, v)``:
  FISHEYE / SIMPLE_FISHEYE ``theta_d = theta``; SIMPLE_RADIAL_FISHEYE ``theta (1 + k theta^2)``;
  RADIAL_FISHEYE ``theta (1 + k1 theta^2 + k2 theta^4)``; OPENCV_FISHEYE ``theta (1 + k1 theta^2 + ...
  + k4 theta^8)``;
* THIN_PRISM_FISHEYE: the equidistant point ``(a, b) = (theta / r) (u, v)``, ``s = a^2 + b^2``, then
  ``a (1 + k1 s + k2 s^2 + k3 s^3 + k4 s^4) + 2 p1 a b + p2 (s + 2 a^2) + sx1 s`` and its twin for b;
* FOV ``omega``: ``(u_d, v_d) = (atan(2 r tan(omega / 2)) / (omega r)) (u, v)``, with COLMAP's series for
  small omega or r (:func:`_fov_factor`), so that small-omega cameras match COLMAP to the last bit.

The inverse ``D^-1`` is Newton's method with a central-difference Jacobian (its accuracy is decided by
the forward residual, checked in normalised coordinates against ``UNDISTORT_RTOL``, not by the Jacobian).  The other
perspective models (RAD_TAN_THIN_PRISM_FISHEYE, SIMPLE_DIVISION, DIVISION, EUCM, and any later one) go
through ``pycolmap.Camera.cam_from_img`` when pycolmap is installed, polished by the same Newton iteration on
``img_from_cam`` to the same tolerance.  EQUIRECTANGULAR (a sphere, no pinhole ray for half the directions)
cannot be used.
"""
from __future__ import annotations

import functools

import numpy as np

__all__ = ["OWN_MODELS", "PYCOLMAP_MODELS", "NON_PERSPECTIVE_MODELS", "split_params", "forward", "inverse",
           "central_inverse", "keep_central", "pycolmap_camera", "FOLD_SAMPLES", "radial_fold_image"]

#: model -> (names of PARAMS[], focal layout) for the models with own code below; "f" = one focal.
OWN_MODELS = {
    "FULL_OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"),
    "OPENCV_FISHEYE": ("fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"),
    "SIMPLE_RADIAL_FISHEYE": ("f", "cx", "cy", "k"),
    "RADIAL_FISHEYE": ("f", "cx", "cy", "k1", "k2"),
    "THIN_PRISM_FISHEYE": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "sx1", "sy1"),
    "FOV": ("fx", "fy", "cx", "cy", "omega"),
    "SIMPLE_FISHEYE": ("f", "cx", "cy"),
    "FISHEYE": ("fx", "fy", "cx", "cy"),
}
#: perspective models used through pycolmap (when installed).
PYCOLMAP_MODELS = ("RAD_TAN_THIN_PRISM_FISHEYE", "SIMPLE_DIVISION", "DIVISION", "EUCM")
#: models without a pinhole form: never usable for triangulation.
NON_PERSPECTIVE_MODELS = ("EQUIRECTANGULAR",)

_EPS = 1e-12          # below this r the fisheye maps are the identity to first order (their limit)


def split_params(model: str, params) -> tuple[float, float, float, float, dict]:
    """(fx, fy, cx, cy, {extra name: value}) of a model of :data:`OWN_MODELS`."""
    names = OWN_MODELS[model]
    p = dict(zip(names, (float(v) for v in params)))
    f = p.pop("f", None)
    fx, fy = (f, f) if f is not None else (p.pop("fx"), p.pop("fy"))
    return fx, fy, p.pop("cx"), p.pop("cy"), p


def _equidistant(u, v):
    """(theta / r) (u, v) and theta, with the limit (u, v), r for r -> 0."""
    r = np.hypot(u, v)
    theta = np.arctan(r)
    s = np.where(r > _EPS, theta / np.where(r > _EPS, r, 1.0), 1.0)
    return u * s, v * s, theta


def forward(model: str, extra: dict, uv: np.ndarray) -> np.ndarray:
    """D(u, v) of ``model`` (module docstring) for (M, 2) normalised coordinates."""
    u, v = uv[:, 0], uv[:, 1]
    e = extra
    if model == "FULL_OPENCV":
        r2 = u * u + v * v
        num = 1 + r2 * (e["k1"] + r2 * (e["k2"] + r2 * e["k3"]))
        radial = num / (1 + r2 * (e["k4"] + r2 * (e["k5"] + r2 * e["k6"])))
        return np.column_stack([u * radial + 2 * e["p1"] * u * v + e["p2"] * (r2 + 2 * u * u),
                                v * radial + 2 * e["p2"] * u * v + e["p1"] * (r2 + 2 * v * v)])
    if model == "FOV":
        return uv * _fov_factor(e["omega"], u * u + v * v)[:, None]
    a, b, theta = _equidistant(u, v)
    if model in ("FISHEYE", "SIMPLE_FISHEYE"):
        return np.column_stack([a, b])
    if model == "THIN_PRISM_FISHEYE":
        s = a * a + b * b
        radial = 1 + s * (e["k1"] + s * (e["k2"] + s * (e["k3"] + s * e["k4"])))
        return np.column_stack([a * radial + 2 * e["p1"] * a * b + e["p2"] * (s + 2 * a * a) + e["sx1"] * s,
                                b * radial + 2 * e["p2"] * a * b + e["p1"] * (s + 2 * b * b) + e["sy1"] * s])
    t2 = theta * theta
    ks = {"SIMPLE_RADIAL_FISHEYE": ("k",), "RADIAL_FISHEYE": ("k1", "k2"),
          "OPENCV_FISHEYE": ("k1", "k2", "k3", "k4")}[model]
    poly = np.zeros_like(t2)
    for k in reversed(ks):
        poly = (poly + e[k]) * t2
    return np.column_stack([a, b]) * (1 + poly)[:, None]


def _fov_factor(w: float, r2: np.ndarray) -> np.ndarray:
    """The FOV model's radial factor, with COLMAP's own branches (so that ERROR is COLMAP's): its series in
    omega^2 below :data:`FOV_EPS`, its series in r^2 below it, else ``atan(2 r tan(omega / 2)) / (omega r)``."""
    w2 = w * w
    if w2 < FOV_EPS:
        return (w2 * r2) / 3 - w2 / 12 + 1
    th = np.tan(w / 2)
    small = r2 < FOV_EPS
    r = np.sqrt(np.where(small, 1.0, r2))
    exact = np.arctan(r * 2 * th) / (r * w)
    return np.where(small, (-2 * th * (4 * r2 * th * th - 3)) / (3 * w), exact)


#: COLMAP's switch between the FOV model's series and its closed form (``kEpsilon`` in models.h).
FOV_EPS = 1e-4


#: starts of :func:`central_inverse` after ``uv_d`` itself, as fractions of it (towards the image centre).
CENTRAL_STARTS = (0.5, 0.25, 0.1)
#: steps of the continuation from the centre that :func:`central_inverse` falls back on.
CONTINUATION_STEPS = 16


def central_inverse(model: str, extra: dict, uv_d: np.ndarray, tol: float, max_iter: int
                    ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`inverse` of :func:`forward` that keeps only roots on the branch the model describes from the image
    centre (:func:`_central`: on the distorted point's side of the axis, D orientation-preserving there -- not past a
    fold -- and for FULL_OPENCV before the first pole of its rational factor).  Newton's method from ``uv_d`` can
    cross a pole or a fold to another root, converged in the pixel sense (review 30a F3: |u| = 8.6 beyond a pole at
    1.12, where a same-side root at |u| = 0.71 exists; review 30b F1: a root past a fold), or diverge (30a F5: FOV at
    omega = 3): such rows start again nearer the centre (:data:`CENTRAL_STARTS`), then follow the central branch
    from the centre to ``uv_d`` in :data:`CONTINUATION_STEPS` steps, and are refused (not converged) when that does
    not reach a central root either."""
    uv, ok = inverse(lambda p: forward(model, extra, p), uv_d, tol, max_iter)
    return keep_central(model, extra, uv_d, uv, ok, tol, max_iter)


def keep_central(model: str, extra: dict, uv_d: np.ndarray, uv: np.ndarray, ok: np.ndarray, tol: float,
                 max_iter: int) -> tuple[np.ndarray, np.ndarray]:
    """Roots ``uv`` (converged where ``ok``) of D(uv) = uv_d from any solver, kept where they lie on the central
    branch; the other rows searched again as :func:`central_inverse` does (the work after its own first Newton
    solve: the OPENCV family's analytic Newton hands its roots here).  ``uv`` is updated in place."""
    fun = lambda p: forward(model, extra, p)      # noqa: E731
    bad = ~(ok & _central(model, extra, uv, uv_d))
    refused = np.zeros(len(uv_d), bool)
    if model == "FULL_OPENCV" and bad.any():        # beyond the image of the central branch: no root to look for
        refused = bad & (np.hypot(uv_d[:, 0], uv_d[:, 1]) > radial_fold_image(extra))
        bad &= ~refused
    for s in CENTRAL_STARTS + (None,):
        if not bad.any():
            break
        idx = np.nonzero(bad)[0]
        if s is None:
            uv2, ok2 = _continuation(model, extra, uv_d[idx], tol, max_iter)
        else:
            uv2, ok2 = inverse(fun, uv_d[idx], tol, max_iter, start=s * uv_d[idx])
        good = ok2 & _central(model, extra, uv2, uv_d[idx])
        uv[idx[good]] = uv2[good]
        bad[idx[good]] = False
    return uv, ~(bad | refused)


def radial_fold_image(extra: dict) -> float:
    """FULL_OPENCV without tangential terms: the largest distorted radius its central branch reaches, i.e. g(r) =
    r N(r^2) / M(r^2) (N = 1 + k1 s + k2 s^2 + k3 s^3, M = 1 + k4 s + k5 s^2 + k6 s^3) at its first fold -- the
    smallest s = r^2 > 0 where (N + 2 s N') M - 2 s N M' = 0 -- times 1 + 1e-9; inf where g does not fold, a pole of
    M comes first, or p1, p2 are not 0 (then nothing is skipped)."""
    e = extra
    if e["p1"] or e["p2"]:
        return np.inf
    s_fold, s_pole = _radial_limits(tuple(float(e[k]) for k in ("k1", "k2", "k3", "k4", "k5", "k6")))
    if not (s_fold < s_pole and np.isfinite(s_fold)):
        return np.inf
    r = float(np.sqrt(s_fold))
    N = 1.0 + s_fold * (e["k1"] + s_fold * (e["k2"] + s_fold * e["k3"]))
    M = 1.0 + s_fold * (e["k4"] + s_fold * (e["k5"] + s_fold * e["k6"]))
    return abs(r * N / M) * (1.0 + 1e-9)


@functools.lru_cache(maxsize=256)
def _radial_limits(k: tuple) -> tuple[float, float]:
    """(s_fold, s_pole): the smallest s = r^2 > 0 where FULL_OPENCV's radial map g(r) = r N(s) / M(s) stops rising
    ((N + 2 s N') M - 2 s N M' = 0) and where M vanishes (inf where none)."""
    N = np.polynomial.Polynomial([1.0, k[0], k[1], k[2]])
    M = np.polynomial.Polynomial([1.0, k[3], k[4], k[5]])
    S = np.polynomial.Polynomial([0.0, 1.0])
    slope = (N + 2 * S * N.deriv()) * M - 2 * S * N * M.deriv()

    def first(p):
        z = p.trim().roots() if p.trim().degree() > 0 else np.array([])
        r = [float(v.real) for v in np.atleast_1d(z) if abs(v.imag) <= 1e-9 * max(1.0, abs(v)) and v.real > 0]
        return min(r) if r else np.inf
    return first(slope), first(M)


def _continuation(model: str, extra: dict, uv_d: np.ndarray, tol: float, max_iter: int):
    """Roots of D(uv) = uv_d followed from the centre: Newton's method on t uv_d for t = 1/K, 2/K, ..., 1, each step
    started at the root of the step before and kept only while it stays central."""
    uv = np.zeros_like(uv_d)
    ok = np.ones(len(uv_d), bool)
    for t in np.arange(1, CONTINUATION_STEPS + 1) / CONTINUATION_STEPS:
        idx = np.nonzero(ok)[0]
        if not idx.size:
            break
        uv2, ok2 = inverse(lambda p: forward(model, extra, p), t * uv_d[idx], tol, max_iter, start=uv[idx])
        ok2 &= _central(model, extra, uv2, t * uv_d[idx], samples=1)      # (the whole segment at the end)
        ok[idx[~ok2]] = False
        uv[idx[ok2]] = uv2[ok2]
    ok[ok] = _central(model, extra, uv[ok], uv_d[ok])
    return uv, ok


#: points of the segment from the centre to a root at which :func:`_central` checks that D does not fold
FOLD_SAMPLES = 16


def _central(model: str, extra: dict, uv: np.ndarray, uv_d: np.ndarray, samples: int = FOLD_SAMPLES) -> np.ndarray:
    """(M,) whether each root lies on the central branch (:func:`central_inverse`): the side of ``uv_d``, and on the
    segment from the centre to the root (at t uv, t = 1/K, ..., 1, K = ``samples``) det of D's Jacobian > 0
    (central differences) and for FULL_OPENCV a positive denominator.  The root's own Jacobian is not enough: past
    a fold where D rises again (k1 = -0.5, k2 = 0.1: a fold at r = 1, a minimum of D at 1.41) a third-branch root
    has det > 0 (review 44b HIGH-1)."""
    fun = lambda p: forward(model, extra, p)      # noqa: E731
    with np.errstate(all="ignore"):
        ok = (np.sum(uv * uv_d, axis=1) > 0) | np.all(uv_d == 0, axis=1)
        if model == "FULL_OPENCV" and not (extra["p1"] or extra["p2"]):
            # radially symmetric: det J = g'(r) g(r) / r > 0 on the segment iff r^2 is below the first fold and pole
            s_fold, s_pole = _radial_limits(tuple(float(extra[k]) for k in ("k1", "k2", "k3", "k4", "k5", "k6")))
            return ok & (np.sum(uv * uv, axis=1) < min(s_fold, s_pole))
        jac = (lambda p: _full_opencv_jacobian(extra, p)) if model == "FULL_OPENCV" else \
            (lambda p: _jacobian(fun, p))
        for k in range(samples, 0, -1):
            if not ok.any():
                break
            p = uv[ok] * (k / samples)
            J = jac(p)
            good = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0] > 0
            if model == "FULL_OPENCV":
                r2 = np.sum(p * p, axis=1)
                good &= 1 + r2 * (extra["k4"] + r2 * (extra["k5"] + r2 * extra["k6"])) > 0
            ok[np.nonzero(ok)[0][~good]] = False
    return ok


def _full_opencv_jacobian(e: dict, uv: np.ndarray) -> np.ndarray:
    """(M, 2, 2) analytic Jacobians of FULL_OPENCV's map (module docstring) at the rows of ``uv``: with s = r^2,
    radial = N(s) / M(s) and d radial / du = 2 u (N' M - N M') / M^2 (the sign of det J is what :func:`_central`
    reads; four forward maps per central difference cost 8x the numpy calls)."""
    u, v = uv[:, 0], uv[:, 1]
    s = u * u + v * v
    N = 1 + s * (e["k1"] + s * (e["k2"] + s * e["k3"]))
    Nd = e["k1"] + s * (2 * e["k2"] + s * 3 * e["k3"])
    M = 1 + s * (e["k4"] + s * (e["k5"] + s * e["k6"]))
    Md = e["k4"] + s * (2 * e["k5"] + s * 3 * e["k6"])
    radial = N / M
    dr = 2.0 * (Nd * M - N * Md) / (M * M)              # d radial / d u = dr u, d radial / d v = dr v
    p1, p2 = e["p1"], e["p2"]
    J = np.empty((len(uv), 2, 2))
    J[:, 0, 0] = radial + dr * u * u + 2 * p1 * v + 6 * p2 * u
    J[:, 0, 1] = dr * u * v + 2 * p1 * u + 2 * p2 * v
    J[:, 1, 0] = dr * u * v + 2 * p2 * v + 2 * p1 * u
    J[:, 1, 1] = radial + dr * v * v + 2 * p2 * u + 6 * p1 * v
    return J


def inverse(fun, uv_d: np.ndarray, tol: float, max_iter: int, start: np.ndarray | None = None
            ) -> tuple[np.ndarray, np.ndarray]:
    """Solve ``fun(uv) = uv_d`` (fun: (M, 2) -> (M, 2)) by Newton's method from ``uv = start`` (default ``uv_d``)
    with a central-difference Jacobian; ``(uv, converged)`` with converged = ``|fun(uv) - uv_d|_inf <= tol``."""
    uv = (uv_d if start is None else np.asarray(start, float)).copy()
    active = np.ones(len(uv), bool)
    with np.errstate(all="ignore"):
        for _ in range(max_iter):
            res = fun(uv) - uv_d
            active &= ~np.all(np.abs(res) <= tol, axis=1)
            if not active.any():
                break
            J = _jacobian(fun, uv)
            det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
            active &= np.isfinite(det) & (det != 0)
            safe = np.where(active, det, 1.0)
            step = np.column_stack([J[:, 1, 1] * res[:, 0] - J[:, 0, 1] * res[:, 1],
                                    J[:, 0, 0] * res[:, 1] - J[:, 1, 0] * res[:, 0]]) / safe[:, None]
            uv = np.where(active[:, None], uv - step, uv)
        res = fun(uv) - uv_d
    ok = np.all(np.isfinite(uv), axis=1) & np.all(np.abs(res) <= tol, axis=1)
    return uv, ok


def _jacobian(fun, uv: np.ndarray) -> np.ndarray:
    """(M, 2, 2) central-difference Jacobians of ``fun`` at the rows of ``uv`` (steps 1e-7 max(1, |uv|))."""
    h = 1e-7 * np.maximum(1.0, np.abs(uv))
    J = np.empty((len(uv), 2, 2))
    for j in range(2):
        d = np.zeros_like(uv)
        d[:, j] = h[:, j]
        J[:, :, j] = (fun(uv + d) - fun(uv - d)) / (2 * h[:, j:j + 1])
    return J


def pycolmap_camera(model: str, params):
    """A ``pycolmap.Camera`` of the model (ImportError when pycolmap is not installed)."""
    import pycolmap

    return pycolmap.Camera(model=model, width=1, height=1, params=[float(v) for v in params])
