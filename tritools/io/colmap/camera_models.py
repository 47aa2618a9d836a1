"""COLMAP camera models: intrinsics K, lens distortion and its inverse.

COLMAP maps a point ``X_cam = (x, y, z)`` in camera coordinates (``cam_from_world``)
to pixels in three steps: normalised coordinates ``(u, v) = (x / z, y / z)``, lens
distortion ``(u_d, v_d) = D(u, v)``, then ``(px, py) = (fx u_d + cx, fy v_d + cy)``.
The supported models are special cases of COLMAP's ``OPENCV`` model

    r^2 = u^2 + v^2,   radial = k1 r^2 + k2 r^4,
    u_d = u (1 + radial) + 2 p1 u v + p2 (r^2 + 2 u^2),
    v_d = v (1 + radial) + 2 p2 u v + p1 (r^2 + 2 v^2),

with parameters (in COLMAP's ``cameras.txt`` order):

=============== ================================ ======================
model           PARAMS[]                         as OPENCV
=============== ================================ ======================
SIMPLE_PINHOLE  f, cx, cy                        fx = fy = f, k = p = 0
PINHOLE         fx, fy, cx, cy                   k = p = 0
SIMPLE_RADIAL   f, cx, cy, k                     k1 = k, k2 = p = 0
RADIAL          f, cx, cy, k1, k2                p = 0
OPENCV          fx, fy, cx, cy, k1, k2, p1, p2   itself
=============== ================================ ======================

and, beyond them, every other perspective COLMAP model: FULL_OPENCV, the fisheye models
(OPENCV_FISHEYE, SIMPLE_RADIAL_FISHEYE, RADIAL_FISHEYE, THIN_PRISM_FISHEYE, FISHEYE,
SIMPLE_FISHEYE) and FOV with own code (:mod:`.lens`), RAD_TAN_THIN_PRISM_FISHEYE,
SIMPLE_DIVISION, DIVISION and EUCM through ``pycolmap.Camera.cam_from_img`` when pycolmap is
installed.  EQUIRECTANGULAR (spherical) is read and written, but has no pinhole form: its
cameras cannot be used for triangulation (:func:`camera_problem` says why).

Triangulation (SPEC §1) needs pinhole cameras ``P = K [R | t]``, so observed pixels are
first *undistorted*: ``(u, v) = D^-1(K^-1 (px, py))`` by Newton's method, and mapped back
to pixels with the same K.  gamma is then measured in **undistorted pixel coordinates**
(the image of an ideal pinhole camera with the same K), not in the recorded image; the
two agree to first order where the distortion is small.
"""
from __future__ import annotations

import enum
import functools

import numpy as np

from .lens import NON_PERSPECTIVE_MODELS, PYCOLMAP_MODELS, pycolmap_camera, split_params
from .lens import central_inverse, forward as lens_forward, inverse as lens_inverse, keep_central

__all__ = ["CameraModel", "COLMAP_MODEL_N_PARAMS", "COLMAP_MODEL_IDS", "COLMAP_MODEL_NAMES", "UNDISTORT_RTOL",
           "undistort_tolerance", "UNDISTORT_MAX_ITER", "UnsupportedCameraModelError", "camera_model", "camera_problem",
           "intrinsics",
           "distortion", "distort", "distort_rows", "undistort", "pixels_from_camera", "undistorted_pixels",
           "OPENCV_FAMILY", "usable_models"]

#: Newton's iteration for D^-1 stops when the forward model reproduces the observed normalised coordinates
#: (u_d, v_d) = ((x - cx) / fx, (y - cy) / fy) to this relative accuracy (of max(1, the call's median |u_d|_inf):
#: :func:`undistort_tolerance`) -- a few ulps, the round-off of the coordinates themselves, whatever the focal length
#: and the pixel unit.  An absolute pixel tolerance (1e-10 px before wave 50) was 1e-4 of the noise of cameras
#: calibrated in metres on the sensor (f ~ 1e-3: lower bounds 3e-5..7.5e-5 relative above the optimum of the exactly
#: undistorted keypoints) and below one ulp at f >= 1e7 (in-image keypoints refused; review 50a F1, F3).
UNDISTORT_RTOL = 16 * 2.0 ** -52
#: ... or gives up after this many iterations (Newton converges quadratically; 5-8 steps
#: suffice for the distortions of real lenses within their image).
UNDISTORT_MAX_ITER = 50

#: number of PARAMS[] of every model COLMAP knows (used to check cameras.txt / cameras.bin; only
#: the models of :class:`CameraModel` can be used for triangulation).
COLMAP_MODEL_N_PARAMS = {
    "SIMPLE_PINHOLE": 3, "PINHOLE": 4, "SIMPLE_RADIAL": 4, "RADIAL": 5, "OPENCV": 8, "OPENCV_FISHEYE": 8,
    "FULL_OPENCV": 12, "FOV": 5, "SIMPLE_RADIAL_FISHEYE": 4, "RADIAL_FISHEYE": 5, "THIN_PRISM_FISHEYE": 12,
    "RAD_TAN_THIN_PRISM_FISHEYE": 16, "SIMPLE_DIVISION": 4, "DIVISION": 5, "SIMPLE_FISHEYE": 3, "FISHEYE": 4,
    "EUCM": 6, "EQUIRECTANGULAR": 2,
}
#: COLMAP's numeric model ids (``cameras.bin``; ``CameraModelId`` in COLMAP's sensor/models.h).
COLMAP_MODEL_IDS = {
    "SIMPLE_PINHOLE": 0, "PINHOLE": 1, "SIMPLE_RADIAL": 2, "RADIAL": 3, "OPENCV": 4, "OPENCV_FISHEYE": 5,
    "FULL_OPENCV": 6, "FOV": 7, "SIMPLE_RADIAL_FISHEYE": 8, "RADIAL_FISHEYE": 9, "THIN_PRISM_FISHEYE": 10,
    "RAD_TAN_THIN_PRISM_FISHEYE": 11, "SIMPLE_DIVISION": 12, "DIVISION": 13, "SIMPLE_FISHEYE": 14, "FISHEYE": 15,
    "EUCM": 16, "EQUIRECTANGULAR": 17,
}
#: model id -> name.
COLMAP_MODEL_NAMES = {v: k for k, v in COLMAP_MODEL_IDS.items()}


class CameraModel(str, enum.Enum):
    """The COLMAP camera models tritools undistorts with its own code (the module table and :mod:`.lens`);
    the models of :data:`.lens.PYCOLMAP_MODELS` are used through pycolmap when it is installed."""
    SIMPLE_PINHOLE = "SIMPLE_PINHOLE"
    PINHOLE = "PINHOLE"
    SIMPLE_RADIAL = "SIMPLE_RADIAL"
    RADIAL = "RADIAL"
    OPENCV = "OPENCV"
    FULL_OPENCV = "FULL_OPENCV"
    OPENCV_FISHEYE = "OPENCV_FISHEYE"
    SIMPLE_RADIAL_FISHEYE = "SIMPLE_RADIAL_FISHEYE"
    RADIAL_FISHEYE = "RADIAL_FISHEYE"
    THIN_PRISM_FISHEYE = "THIN_PRISM_FISHEYE"
    FOV = "FOV"
    SIMPLE_FISHEYE = "SIMPLE_FISHEYE"
    FISHEYE = "FISHEYE"


#: the special cases of OPENCV (module table): (k1, k2, p1, p2) describe their distortion.
OPENCV_FAMILY = ("SIMPLE_PINHOLE", "PINHOLE", "SIMPLE_RADIAL", "RADIAL", "OPENCV")


@functools.lru_cache(maxsize=1)
def _pycolmap_available() -> bool:
    try:
        import pycolmap  # noqa: F401
    except ImportError:
        return False
    return True


def usable_models() -> tuple[str, ...]:
    """The COLMAP models usable for triangulation here (own code, plus pycolmap's when installed)."""
    return tuple(m.value for m in CameraModel) + (PYCOLMAP_MODELS if _pycolmap_available() else ())


class UnsupportedCameraModelError(ValueError):
    """A COLMAP camera model that tritools cannot turn into a pinhole camera."""


def camera_model(name: str) -> CameraModel:
    """The :class:`CameraModel` of a name, or UnsupportedCameraModelError naming it (and why)."""
    try:
        return CameraModel(name)
    except ValueError:
        pass
    if name in NON_PERSPECTIVE_MODELS:
        why = "a spherical model: no pinhole camera K [R | t] sees its rays"
    elif name in PYCOLMAP_MODELS:
        why = "it is used through pycolmap, which is not installed (pip install 'sospoly-tritools[colmap]')"
    else:
        why = "not a COLMAP camera model tritools knows"
    raise UnsupportedCameraModelError(f"camera model {name!r} is not supported for triangulation ({why}; "
                                      f"usable: {', '.join(usable_models())})")


def camera_problem(model: str, params) -> str | None:
    """Why a camera cannot be used for triangulation (``None`` when it can): an unsupported
    model, a wrong number of parameters, non-finite parameters or a focal length <= 0."""
    try:
        c = _Lens(model, params)
    except ValueError as exc:
        return str(exc)
    fx, fy = c.fx, c.fy
    bad = [name for name, v in (("fx", fx), ("fy", fy)) if not (np.isfinite(v) and v > 0)]
    if bad:
        return ", ".join(f"focal length {n} = {v!r} must be > 0" for n, v in (("fx", fx), ("fy", fy)) if n in bad)
    if not np.all(np.isfinite([float(v) for v in params])):
        return "parameters must be finite"
    with np.errstate(over="ignore", divide="ignore"):
        tiny = [n for n, v in (("fx", fx), ("fy", fy)) if not np.isfinite(1.0 / np.float64(v))]
    if tiny:            # (a subnormal focal length: undistortion divides by it and returned -inf as "converged")
        return ", ".join(f"focal length {n} = {v!r} is too small (1/{n} overflows)" for n, v in (("fx", fx), ("fy", fy))
                         if n in tiny)
    return None


def _split(model: str, params) -> tuple[float, float, float, float, np.ndarray]:
    """(fx, fy, cx, cy, [k1, k2, p1, p2]) of a model of :data:`OPENCV_FAMILY`."""
    m = camera_model(model)
    p = [float(v) for v in params]
    expected = COLMAP_MODEL_N_PARAMS[m.value]
    if len(p) != expected:
        raise ValueError(f"camera model {m.value} needs {expected} params, got {len(p)}")
    if m == CameraModel.SIMPLE_PINHOLE:
        f, cx, cy = p
        return f, f, cx, cy, np.zeros(4)
    if m == CameraModel.PINHOLE:
        fx, fy, cx, cy = p
        return fx, fy, cx, cy, np.zeros(4)
    if m == CameraModel.SIMPLE_RADIAL:
        f, cx, cy, k = p
        return f, f, cx, cy, np.array([k, 0.0, 0.0, 0.0])
    if m == CameraModel.RADIAL:
        f, cx, cy, k1, k2 = p
        return f, f, cx, cy, np.array([k1, k2, 0.0, 0.0])
    if m == CameraModel.OPENCV:
        fx, fy, cx, cy, k1, k2, p1, p2 = p
        return fx, fy, cx, cy, np.array([k1, k2, p1, p2])
    raise UnsupportedCameraModelError(f"camera model {model!r} has no OPENCV (k1, k2, p1, p2) form")


class _Lens:
    """One camera's K and its distortion map D on normalised coordinates, whatever the model."""

    def __init__(self, model: str, params):
        if model in OPENCV_FAMILY:
            self.fx, self.fy, self.cx, self.cy, self.dist = _split(model, params)
            self.D = lambda uv: distort(uv, self.dist)
            self.camera = None
            return
        try:
            camera_model(model)
            own = True
        except UnsupportedCameraModelError:
            if model not in PYCOLMAP_MODELS or not _pycolmap_available():
                raise
            own = False
        n = COLMAP_MODEL_N_PARAMS[model]
        if len(params) != n:
            raise ValueError(f"camera model {model} needs {n} params, got {len(params)}")
        if own:
            self.fx, self.fy, self.cx, self.cy, extra = split_params(model, params)
            self.D = lambda uv: lens_forward(model, extra, uv)
            self.inverse = lambda uv_d, tol: central_inverse(model, extra, uv_d, tol, UNDISTORT_MAX_ITER)
            self.camera = None
        else:
            c = self.camera = pycolmap_camera(model, params)
            self.fx, self.fy, self.cx, self.cy = (c.focal_length_x, c.focal_length_y, c.principal_point_x,
                                                  c.principal_point_y)
            self.D = None
        self.dist = None

    def pixels(self, X_cam: np.ndarray) -> np.ndarray:
        if self.camera is not None:
            with np.errstate(all="ignore"):
                return np.asarray(self.camera.img_from_cam(np.ascontiguousarray(X_cam, float)), float)
        uv = self.D(X_cam[:, :2] / X_cam[:, 2:3])
        return np.column_stack([self.fx * uv[:, 0] + self.cx, self.fy * uv[:, 1] + self.cy])

    def undistort(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Normalised (u, v) of observed pixels and whether D(u, v) reproduces their normalised coordinates to
        :func:`undistort_tolerance`."""
        uv_d = np.column_stack([(xy[:, 0] - self.cx) / self.fx, (xy[:, 1] - self.cy) / self.fy])
        tol = undistort_tolerance(uv_d)
        if self.dist is not None:
            uv, ok = undistort(uv_d, self.dist)
            return _central_rows(uv, ok, uv_d, self.dist, tol)
        if self.camera is None:
            return self.inverse(uv_d, tol)
        with np.errstate(all="ignore"):
            start = np.asarray(self.camera.cam_from_img(np.ascontiguousarray(xy, float)), float).reshape(-1, 2)
        found = np.all(np.isfinite(start), axis=1)       # pycolmap's inverse, polished to the tolerance on its forward
        uv, ok = lens_inverse(self._normalised_forward, uv_d, tol, UNDISTORT_MAX_ITER,
                              start=np.where(found[:, None], start, uv_d))
        return uv, ok & found

    def _normalised_forward(self, uv: np.ndarray) -> np.ndarray:
        """D(u, v) of a pycolmap model: its pixels of the camera-frame points (u, v, 1), normalised."""
        xy = self.pixels(np.column_stack([uv, np.ones(len(uv))]))
        return np.column_stack([(xy[:, 0] - self.cx) / self.fx, (xy[:, 1] - self.cy) / self.fy])


def undistort_tolerance(uv_d: np.ndarray) -> float:
    """The undistortion's tolerance on the forward residual in normalised coordinates: ``UNDISTORT_RTOL``
    max(1, median over the finite rows of |uv_d|_inf) (the median: one keypoint far off the image does not loosen the
    others)."""
    a = np.max(np.abs(np.asarray(uv_d, float).reshape(-1, 2)), axis=1)
    a = a[np.isfinite(a)]
    return UNDISTORT_RTOL * max(1.0, float(np.median(a)) if len(a) else 1.0)


def _central_rows(uv: np.ndarray, ok: np.ndarray, uv_d: np.ndarray, dist: np.ndarray, tol: float) -> tuple:
    """The OPENCV family's Newton roots kept where they lie on the central branch (the rule of the own models on
    OPENCV's map, FULL_OPENCV with k3..k6 = 0: :func:`~.lens.keep_central`); the other rows searched again as
    :func:`~.lens.central_inverse` does, refused where no central root is found.  Newton's method from the keypoint
    crossed the fold of a negative k to a root on the other side of the axis, or to one past the fold, and such
    keypoints were certified (review 44b HIGH-1: SIMPLE_RADIAL f = 300, k = -0.3, a keypoint inside the image 280 px
    from its centre)."""
    if not np.any(dist):
        return uv, ok
    extra = dict(zip(("k1", "k2", "p1", "p2"), (float(v) for v in dist)), k3=0.0, k4=0.0, k5=0.0, k6=0.0)
    return keep_central("FULL_OPENCV", extra, uv_d, uv.copy(), ok, tol, UNDISTORT_MAX_ITER)


def intrinsics(model: str, params) -> np.ndarray:
    """K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (COLMAP has no skew) of any usable model."""
    c = _Lens(model, params)
    return np.array([[c.fx, 0.0, c.cx], [0.0, c.fy, c.cy], [0.0, 0.0, 1.0]])


def distortion(model: str, params) -> np.ndarray:
    """(k1, k2, p1, p2) of the OPENCV form of a model of :data:`OPENCV_FAMILY` (zeros for pinhole models);
    UnsupportedCameraModelError for the other models, which have no such form."""
    return _split(model, params)[4]


def distort(uv: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """D(u, v) of the module docstring, for an (M, 2) array of normalised coordinates."""
    k1, k2, p1, p2 = dist
    u, v = uv[:, 0], uv[:, 1]
    r2 = u * u + v * v
    radial = k1 * r2 + k2 * r2 * r2
    return np.column_stack([u * (1 + radial) + 2 * p1 * u * v + p2 * (r2 + 2 * u * u),
                            v * (1 + radial) + 2 * p2 * u * v + p1 * (r2 + 2 * v * v)])


def distort_rows(uv: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """D(u, v) with one set of coefficients per row: uv (M, 2), dist (M, 4) = (k1, k2, p1, p2)."""
    k1, k2, p1, p2 = (dist[:, j] for j in range(4))
    u, v = uv[:, 0], uv[:, 1]
    r2 = u * u + v * v
    radial = k1 * r2 + k2 * r2 * r2
    return np.column_stack([u * (1 + radial) + 2 * p1 * u * v + p2 * (r2 + 2 * u * u),
                            v * (1 + radial) + 2 * p2 * u * v + p1 * (r2 + 2 * v * v)])


def _jacobian(uv: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """dD/d(u, v), shape (M, 2, 2)."""
    k1, k2, p1, p2 = dist
    u, v = uv[:, 0], uv[:, 1]
    r2 = u * u + v * v
    radial = k1 * r2 + k2 * r2 * r2
    drad = 2 * (k1 + 2 * k2 * r2)          # d radial / d u = drad * u, d radial / d v = drad * v
    J = np.empty((len(uv), 2, 2))
    J[:, 0, 0] = 1 + radial + drad * u * u + 2 * p1 * v + 6 * p2 * u
    J[:, 0, 1] = drad * u * v + 2 * p1 * u + 2 * p2 * v
    J[:, 1, 0] = drad * u * v + 2 * p2 * v + 2 * p1 * u
    J[:, 1, 1] = 1 + radial + drad * v * v + 2 * p2 * u + 6 * p1 * v
    return J


def undistort(uv_d: np.ndarray, dist: np.ndarray, scale_px: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Solve D(uv) = uv_d by Newton's method from uv = uv_d.

    Returns ``(uv, converged)``: ``converged[j]`` is True when ``|D(uv_j) - uv_d_j|_inf`` is within
    :func:`undistort_tolerance` of ``uv_d`` (normalised coordinates: the same keypoints converge whatever the focal
    length; ``scale_px`` is accepted for compatibility and not used).
    """
    uv_d = np.asarray(uv_d, float).reshape(-1, 2)
    uv = uv_d.copy()
    if not np.any(dist):
        return uv, np.isfinite(uv).all(axis=1)      # (no distortion: nothing to solve; a non-finite pixel is not)
    tol = undistort_tolerance(uv_d)
    active = np.ones(len(uv), bool)        # rows still iterating (not converged, not stuck)
    with np.errstate(all="ignore"):
        for _ in range(UNDISTORT_MAX_ITER):
            res = distort(uv, dist) - uv_d
            active &= ~np.all(np.abs(res) <= tol, axis=1)
            if not active.any():
                break
            J = _jacobian(uv, dist)          # 2x2 Newton step by Cramer's rule
            det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
            active &= np.isfinite(det) & (det != 0)   # a fold of the distortion: no Newton step
            safe = np.where(active, det, 1.0)
            step = np.column_stack([J[:, 1, 1] * res[:, 0] - J[:, 0, 1] * res[:, 1],
                                    J[:, 0, 0] * res[:, 1] - J[:, 1, 0] * res[:, 0]]) / safe[:, None]
            uv = np.where(active[:, None], uv - step, uv)
        res = distort(uv, dist) - uv_d
    converged = np.all(np.isfinite(uv), axis=1) & np.all(np.abs(res) <= tol, axis=1)
    return uv, converged


def pixels_from_camera(model: str, params, X_cam: np.ndarray) -> np.ndarray:
    """COLMAP's forward projection of (M, 3) camera-frame points to (distorted) pixels, any usable model."""
    return _Lens(model, params).pixels(np.asarray(X_cam, float).reshape(-1, 3))


def undistorted_pixels(model: str, params, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Observed pixels -> pixels of the ideal pinhole camera K (see module docstring), any usable model.

    Returns ``(xy_undistorted (M, 2), converged (M,))``.
    """
    c = _Lens(model, params)
    xy = np.asarray(xy, float).reshape(-1, 2)
    uv, ok = c.undistort(xy)
    return np.column_stack([c.fx * uv[:, 0] + c.cx, c.fy * uv[:, 1] + c.cy]), ok
