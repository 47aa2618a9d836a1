"""Synthetic scenes, the paper's Example 5 protocol and the paper's example data.

* :func:`random_cameras`, :func:`random_scene`: seeded pinhole scenes with cameras on a
  sphere looking at the origin (pixel units).
* :func:`example5_cases`: the 1000-case protocol of the paper's Section 5.5.
* :func:`paper_example`, :func:`paper_table`: Examples 2-4 (SPEC §10), loaded from
  ``tritools/data/paper_examples.json``.
"""
from __future__ import annotations

import copy
import functools
import importlib.resources
import json
from dataclasses import dataclass
from typing import Any

import numpy as np

from .model.geometry import depths, image_points, validate_cameras
from .model.regions import Point, Region

__all__ = [
    "SyntheticScene", "Example5Case", "random_cameras", "random_scene", "example5_cases",
    "example5_cameras", "paper_data", "paper_example", "paper_table",
    "EXAMPLE5_BOX", "EXAMPLE5_MIN_DEPTH",
]

#: Example 5 scene points are drawn uniformly in ``[-EXAMPLE5_BOX, EXAMPLE5_BOX]^3`` ...
EXAMPLE5_BOX = 1.0
#: ... and rejected unless their depth exceeds this value in each of the four views.
EXAMPLE5_MIN_DEPTH = 0.1
#: Maximum rejection-sampling draws per scene point before giving up.
MAX_DRAWS = 100_000


def _rng(seed_or_rng) -> np.random.Generator:
    if isinstance(seed_or_rng, np.random.Generator):
        return seed_or_rng
    return np.random.default_rng(seed_or_rng)


def _readonly(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


# ----------------------------------------------------------------------------- generic scenes
def random_cameras(n_views: int, rng=None, *, radius: float = 10.0, focal: float = 800.0,
                   image_size: tuple[float, float] = (640.0, 480.0)) -> np.ndarray:
    """Pinhole cameras ``P = K [R | -R C]`` with centres ``C`` uniform on the sphere of
    ``radius`` around the origin, optical axes through the origin, random roll, and
    ``K = [[focal, 0, w/2], [0, focal, h/2], [0, 0, 1]]``.

    Returns
    -------
    ndarray, shape (n_views, 3, 4)
    """
    if int(n_views) != n_views or n_views < 1:
        raise ValueError(f"n_views must be a positive integer, got {n_views!r}")
    if not (np.isfinite(radius) and radius > 0):
        raise ValueError(f"radius must be positive, got {radius!r}")
    if not (np.isfinite(focal) and focal > 0):
        raise ValueError(f"focal must be positive, got {focal!r}")
    w, h = (float(v) for v in image_size)
    if not (w > 0 and h > 0):
        raise ValueError(f"image_size must be positive, got {image_size!r}")
    rng = _rng(rng)
    K = np.array([[focal, 0.0, w / 2], [0.0, focal, h / 2], [0.0, 0.0, 1.0]])
    cams = []
    while len(cams) < n_views:
        c = rng.normal(size=3)
        if np.linalg.norm(c) < 1e-6:
            continue
        C = radius * c / np.linalg.norm(c)
        z = -C / np.linalg.norm(C)
        up = rng.normal(size=3)
        x = np.cross(up, z)
        if np.linalg.norm(x) < 1e-6:
            continue
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        R = np.vstack([x, y, z])
        cams.append(K @ np.hstack([R, (-R @ C)[:, None]]))
    return np.array(cams)


@dataclass(frozen=True)
class SyntheticScene:
    """A seeded synthetic scene.

    Attributes
    ----------
    cameras : ndarray (N, 3, 4)
        Projection matrices (world -> pixel, ``cam_from_world`` with intrinsics).
    points3d : ndarray (M, 3)
    points2d_true : ndarray (M, N, 2)
        Exact projections; ``points2d_true[j, i]`` is point j in view i.
    points2d : ndarray (M, N, 2)
        Projections plus Gaussian noise of std ``noise_px`` per coordinate.
    image_size : (width, height)
    noise_px, seed

    Invariants (checked at construction): every point has positive depth in every
    view and every true and noisy image point lies in ``[0, w] x [0, h]``.
    """

    cameras: np.ndarray
    points3d: np.ndarray
    points2d_true: np.ndarray
    points2d: np.ndarray
    image_size: tuple = (640.0, 480.0)
    noise_px: float = 0.0
    seed: Any = None

    def __post_init__(self) -> None:
        C = validate_cameras(self.cameras)
        X = np.array(self.points3d, dtype=float)
        if X.ndim != 2 or X.shape[1] != 3:
            raise ValueError(f"points3d must have shape (M, 3), got {X.shape}")
        M, N = len(X), len(C)
        for name in ("points2d_true", "points2d"):
            a = np.asarray(getattr(self, name), dtype=float)
            if a.shape != (M, N, 2):
                raise ValueError(f"{name} must have shape ({M}, {N}, 2), got {a.shape}")
            if not np.all(np.isfinite(a)):
                raise ValueError(f"{name} contains NaN or inf")
            w, h = self.image_size
            if np.any(a[..., 0] < 0) or np.any(a[..., 0] > w) or np.any(a[..., 1] < 0) or np.any(a[..., 1] > h):
                raise ValueError(f"{name}: some image points fall outside the {w}x{h} image")
            object.__setattr__(self, name, _readonly(a))
        if M and np.any(np.atleast_2d(depths(X, C)) <= 0):
            raise ValueError("points3d: some point is not in front of every camera")
        object.__setattr__(self, "cameras", _readonly(C))
        object.__setattr__(self, "points3d", _readonly(X))

    @property
    def n_views(self) -> int:
        return len(self.cameras)

    @property
    def n_points(self) -> int:
        return len(self.points3d)

    def regions(self, j: int, noisy: bool = True) -> tuple[Region, ...]:
        """Point regions (one per view) of scene point ``j``."""
        pts = self.points2d if noisy else self.points2d_true
        return tuple(Point(x) for x in pts[j])


def random_scene(n_views: int, n_points: int, noise_px: float = 1.0, seed=0, *, radius: float = 10.0,
                 focal: float = 800.0, image_size: tuple = (640.0, 480.0),
                 point_radius: float = 1.0) -> SyntheticScene:
    """Seeded scene: :func:`random_cameras` and ``n_points`` points uniform in the ball
    of ``point_radius`` around the origin (redrawn until visible in every view), with
    Gaussian image noise of standard deviation ``noise_px`` (redrawn if it leaves the image).
    """
    if int(n_points) != n_points or n_points < 0:
        raise ValueError(f"n_points must be a non-negative integer, got {n_points!r}")
    if not (np.isfinite(noise_px) and noise_px >= 0):
        raise ValueError(f"noise_px must be non-negative, got {noise_px!r}")
    if not (np.isfinite(point_radius) and 0 < point_radius < radius):
        raise ValueError(f"point_radius must be in (0, radius), got {point_radius!r}")
    rng = _rng(seed)
    cams = random_cameras(n_views, rng, radius=radius, focal=focal, image_size=image_size)
    w, h = image_size

    def inside(x):
        return np.all((x[..., 0] >= 0) & (x[..., 0] <= w) & (x[..., 1] >= 0) & (x[..., 1] <= h))

    pts, true, noisy = [], [], []
    while len(pts) < n_points:
        for _ in range(MAX_DRAWS):
            u = rng.normal(size=3)
            X = point_radius * rng.uniform() ** (1 / 3) * u / np.linalg.norm(u)
            x = image_points(X, cams)
            if np.all(depths(X, cams) > 0) and inside(x):
                break
        else:
            raise ValueError("could not draw a point visible in every view; reduce point_radius")
        for _ in range(MAX_DRAWS):
            xn = x + noise_px * rng.normal(size=x.shape)
            if inside(xn):
                break
        else:  # pragma: no cover - only for absurd noise levels
            raise ValueError("noise_px too large: noisy points leave the image")
        pts.append(X)
        true.append(x)
        noisy.append(xn)
    n = len(cams)
    return SyntheticScene(cams, np.array(pts).reshape(-1, 3), np.array(true).reshape(-1, n, 2),
                          np.array(noisy).reshape(-1, n, 2), tuple(image_size), float(noise_px), seed)


# ----------------------------------------------------------------------------- paper data
@functools.lru_cache(maxsize=1)
def _paper_json() -> dict:
    text = importlib.resources.files("tritools").joinpath("data/paper_examples.json").read_text("utf-8")
    return json.loads(text)


def paper_data() -> dict:
    """A deep copy of ``paper_examples.json`` (SPEC §10)."""
    return copy.deepcopy(_paper_json())


def _example_key(k) -> str:
    if k not in (2, 3, 4):
        raise ValueError(f"k must be 2, 3 or 4 (the paper's synthetic examples), got {k!r}")
    return f"example{k}"


def paper_example(k: int) -> tuple[np.ndarray, list[Region]]:
    """Cameras (N, 3, 4) and regions of the paper's Example ``k`` (2, 3 or 4)."""
    d = _paper_json()[_example_key(k)]
    return validate_cameras(d["cameras"]), [Region.from_dict(r) for r in d["regions"]]


def paper_table(k: int) -> list[dict]:
    """The paper's result table of Example ``k`` (Table 8, 9, 10 for k = 2, 3, 4)."""
    d = _paper_json()[_example_key(k)]
    return copy.deepcopy(d[f"paper_table{k + 6}"])


# ----------------------------------------------------------------------------- Example 5
@dataclass(frozen=True)
class Example5Case:
    """One case of the paper's Example 5 (Section 5.5).

    Attributes
    ----------
    point_index, theta, trial
        Scene point index (0..n_points-1), uncertainty level, trial index (0..trials-1).
    X_obj : ndarray (3,)
        True scene point.
    cameras_true : ndarray (4, 3, 4)
        Example 4's cameras normalised to unit spectral norm.
    cameras : ndarray (4, 3, 4)
        ``cameras_true`` + uniform noise in ``[-theta, theta]`` per entry.
    image_points_true : ndarray (4, 2)
        Exact projections of ``X_obj``.
    regions : tuple of :class:`Point`
        True projections + uniform noise in ``[-theta A, theta A]`` per coordinate,
        ``A = max_i ||x_i||_2``.
    """

    point_index: int
    theta: float
    trial: int
    X_obj: np.ndarray
    cameras_true: np.ndarray
    cameras: np.ndarray
    image_points_true: np.ndarray
    regions: tuple

    def __post_init__(self) -> None:
        for name in ("X_obj", "cameras_true", "cameras", "image_points_true"):
            object.__setattr__(self, name, _readonly(getattr(self, name)))
        object.__setattr__(self, "regions", tuple(self.regions))

    @property
    def image_points(self) -> np.ndarray:
        """The noisy image points (the centres of the point regions), shape (4, 2)."""
        return np.array([r.center for r in self.regions])


def example5_cameras() -> np.ndarray:
    """Example 4's four cameras, each divided by its spectral norm (``||P_i||_2 = 1``)."""
    C, _ = paper_example(4)
    return C / np.linalg.norm(C, ord=2, axis=(1, 2))[:, None, None]


def example5_cases(seed=0, n_points: int = 25, thetas=(0.05, 0.1, 0.15, 0.2), trials: int = 10,
                   *, box: float = EXAMPLE5_BOX, min_depth: float = EXAMPLE5_MIN_DEPTH) -> list[Example5Case]:
    """The paper's Example 5 protocol (Section 5.5); ``n_points * len(thetas) * trials`` cases.

    1. Cameras: Example 4's ``P_1..P_4`` normalised to unit 2-norm (:func:`example5_cameras`).
    2. ``n_points`` scene points ``X_obj`` uniform in ``[-box, box]^3``, rejected unless
       their depth (Hartley-Zisserman, sign-invariant) exceeds ``min_depth`` in all four
       views (about 3.6% of the box is accepted with the defaults).
    3. For each point, each ``theta`` and each trial (in that nesting order): uniform noise
       in ``[-theta A, theta A]`` on each image coordinate, ``A = max_i ||x_i||_2``, then
       uniform noise in ``[-theta, theta]`` on each entry of each camera.

    All random numbers come from ``numpy.random.default_rng(seed)`` in this order.
    """
    if int(n_points) != n_points or n_points < 1:
        raise ValueError(f"n_points must be a positive integer, got {n_points!r}")
    if int(trials) != trials or trials < 1:
        raise ValueError(f"trials must be a positive integer, got {trials!r}")
    thetas = tuple(float(t) for t in np.atleast_1d(thetas))
    if not thetas or any(not np.isfinite(t) or t < 0 for t in thetas):
        raise ValueError(f"thetas must be non-negative finite numbers, got {thetas!r}")
    if not (np.isfinite(box) and box > 0):
        raise ValueError(f"box must be positive, got {box!r}")
    rng = _rng(seed)
    C = example5_cameras()
    points = []
    for _ in range(int(n_points)):
        for _ in range(MAX_DRAWS):
            X = rng.uniform(-box, box, size=3)
            if np.all(depths(X, C) > min_depth):
                break
        else:
            raise ValueError(f"no point of [-{box}, {box}]^3 with depth > {min_depth} in all views was found")
        points.append(X)
    cases = []
    for j, X in enumerate(points):
        x = image_points(X, C)
        A = float(np.max(np.linalg.norm(x, axis=1)))
        for theta in thetas:
            for trial in range(int(trials)):
                xn = x + rng.uniform(-theta * A, theta * A, size=x.shape)
                Cn = C + rng.uniform(-theta, theta, size=C.shape)
                cases.append(Example5Case(j, theta, trial, X, C, Cn, x, tuple(Point(p) for p in xn)))
    return cases


# ----------------------------------------------------------------------------- uncertain regions
#: region kinds of :func:`uncertain_problem` (``"mixed"`` draws one of them per view).
UNCERTAIN_KINDS = ("point", "segment", "ellipse", "ellipse_border", "polytope")


def uncertain_problem(n_views: int, seed=0, *, noise_px: float = 1.0, size_px: float = 0.5,
                      kinds: str | tuple = "mixed", focal: float = 800.0) -> tuple[np.ndarray, tuple, np.ndarray]:
    """A seeded triangulation problem with *uncertain* regions: ``n_views`` cameras of
    :func:`random_scene`, one scene point observed with Gaussian noise ``noise_px``, and per view a region
    around the noisy observation of about ``size_px`` pixels: a point, a segment (random direction), a
    filled ellipse, an ellipse border (random axes and orientation) or a polytope (a random rotated box).
    ``kinds``: ``"mixed"`` (one drawn per view), one kind, or a tuple of kinds (one per view).

    Returns (cameras (N, 3, 4), regions, the true scene point).  Every region contains its view's noisy
    observation or passes within ``size_px`` of it (the border), so gamma* <= ~noise_px; with regions
    smaller than the noise (the default) gamma* > 0 in general (no point projects into every region).
    """
    from .model.regions import Ellipse, EllipseBorder, Polytope, Segment

    rng = _rng(seed)
    scene = random_scene(n_views, 1, noise_px=noise_px, seed=rng, focal=focal)
    if isinstance(kinds, str):
        kinds = tuple(rng.choice(UNCERTAIN_KINDS) for _ in range(n_views)) if kinds == "mixed" else (kinds,) * n_views
    if len(kinds) != n_views or any(k not in UNCERTAIN_KINDS for k in kinds):
        raise ValueError(f"kinds must be 'mixed', one of {UNCERTAIN_KINDS}, or one per view")
    regions = []
    for x, kind in zip(scene.points2d[0], kinds):
        a = rng.uniform(0, np.pi)
        R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        axes = size_px * rng.uniform(0.4, 1.0, size=2)
        if kind == "point":
            regions.append(Point(x))
        elif kind == "segment":
            regions.append(Segment(x, axes[0] * R[:, 0]))
        elif kind in ("ellipse", "ellipse_border"):
            D = R @ np.diag(axes ** 2) @ R.T
            regions.append((Ellipse if kind == "ellipse" else EllipseBorder)(x, 0.5 * (D + D.T)))
        else:
            B = (R / axes).T                     # ||B (y - x)||_inf <= 1: a rotated box of half widths axes
            regions.append(Polytope(B, -B @ x))
    return scene.cameras, tuple(regions), scene.points3d[0]


__all__ += ["uncertain_problem", "UNCERTAIN_KINDS"]


# ----------------------------------------------------------------------------- the robust-triangulation protocol
#: intrinsics and image size of the CVPR 2023 robust-triangulation protocol (Haerenstam-Nielsen et al.).
PROTOCOL_K = np.array([[1012.0027, 0, 1054], [0, 1012.0027, 581], [0, 0, 1.0]])
PROTOCOL_IMAGE = (2108, 1162)


def sphere_cameras(N: int, rng: np.random.Generator, K: np.ndarray = PROTOCOL_K) -> np.ndarray:
    """N cameras (N, 3, 4) K [R | -R c] with centres c uniform on the sphere of radius 2, each looking at the
    origin (the protocol's cameras; ``rng`` drawn 3 normals per camera)."""
    P = []
    for _ in range(N):
        c = rng.normal(size=3)
        c *= 2.0 / np.linalg.norm(c)
        z = -c / 2.0
        up = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
        ax = np.cross(up, z)
        ax /= np.linalg.norm(ax)
        R = np.stack([ax, np.cross(z, ax), z])
        P.append(K @ np.hstack([R, -R @ c[:, None]]))
    return np.array(P)


def robust_protocol_scene(N: int, n_out: int, noise: float, rng: np.random.Generator):
    """(cameras (N, 3, 4), observations (N, 2), the true point, the outlier mask (N,)) of the protocol:
    :func:`sphere_cameras`, the point uniform in [-0.5, 0.5]^3, Gaussian noise of ``noise`` px, ``n_out``
    observations replaced by uniform points of the image."""
    P = sphere_cameras(N, rng)
    X = rng.uniform(-0.5, 0.5, 3)
    h = P @ np.append(X, 1.0)
    obs = h[:, :2] / h[:, 2:] + noise * rng.normal(size=(N, 2))
    out = np.zeros(N, bool)
    out[rng.choice(N, n_out, replace=False)] = True
    obs[out] = rng.uniform([0, 0], PROTOCOL_IMAGE, size=(n_out, 2))
    return P, obs, X, out


__all__ += ["PROTOCOL_K", "PROTOCOL_IMAGE", "sphere_cameras", "robust_protocol_scene"]


def turntable_cameras(N: int, rng, *, height: float = 0.0, jitter: float = 0.0, radius: float = 2.0,
                      K: np.ndarray = PROTOCOL_K) -> np.ndarray:
    """N cameras (N, 3, 4) ``K [R | -R c]`` on a horizontal circle of ``radius`` at ``height`` (a turntable),
    camera k at angle ``2 pi k / N`` + uniform(-0.2, 0.2) rad, each looking at the origin with its x axis
    horizontal; ``jitter`` adds Gaussian noise of that standard deviation to each centre's height.

    The centres are coplanar (for ``jitter == 0``), the case where Corollary 1's bound stops at the trifocal-plane
    ceiling for points in or near that plane (``tritools.solve.coplanar``).  ``rng`` (a seed or a
    ``numpy.random.Generator``) draws, per camera, one uniform then one normal, whatever ``jitter`` is.
    """
    if int(N) != N or N < 2:
        raise ValueError(f"N must be an integer >= 2, got {N!r}")
    for name, v in (("height", height), ("jitter", jitter), ("radius", radius)):
        if not np.isfinite(v):
            raise ValueError(f"{name} must be finite, got {v!r}")
    if jitter < 0 or radius <= 0:
        raise ValueError(f"jitter must be >= 0 and radius > 0, got jitter={jitter!r}, radius={radius!r}")
    rng = _rng(rng)
    P = []
    for k in range(int(N)):
        a = 2 * np.pi * k / N + rng.uniform(-0.2, 0.2)
        c = np.array([radius * np.cos(a), radius * np.sin(a), height + jitter * rng.normal()])
        z = -c / np.linalg.norm(c)
        ax = np.cross([0.0, 0.0, 1.0], z)
        ax /= np.linalg.norm(ax)
        R = np.stack([ax, np.cross(z, ax), z])
        P.append(K @ np.hstack([R, -R @ c[:, None]]))
    return np.array(P)


__all__ += ["turntable_cameras"]
