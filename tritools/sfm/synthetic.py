"""Seeded synthetic COLMAP models as arrays, for tests, documentation and benchmarks.

:func:`synthetic_arrays` places ``n_images`` cameras on a ring of radius 10 around the origin, all
looking at it (one camera per image, PINHOLE or OPENCV with realistic distortion, f ~ 800 px,
1024 x 768 images), and ``n_points`` scene points in a ball of radius 2.  Each point is seen by a
run of consecutive images (track lengths 1 + a geometric number, mean ~3.5, at most
``max_track``); its keypoints are COLMAP's forward projection (distortion included) plus Gaussian
noise of ``noise_px`` pixels, and each image also gets unmatched keypoints (POINT3D_ID -1).  The
input xyz is the true point moved by ``xyz_noise`` (as a bundle adjuster would leave it).
Everything is vectorised: a million points take a few seconds.
"""
from __future__ import annotations

import numpy as np

from ..io.colmap.arrays import ModelArrays
from ..io.colmap.camera_models import distort_rows
from ..io.colmap.model import qvec_from_rotation

__all__ = ["synthetic_arrays", "OPENCV_DISTORTION"]

#: k1, k2, p1, p2 of the OPENCV variant.
OPENCV_DISTORTION = (-0.12, 0.03, 0.001, -0.0005)


def _look_at(C: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    z = -C / np.linalg.norm(C)
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    R = np.vstack([x, np.cross(z, x), z])
    return R, -R @ C


def synthetic_arrays(n_points: int = 1000, n_images: int = 30, camera: str = "PINHOLE", noise_px: float = 0.5,
                     seed: int = 0, max_track: int = 12, extra_keypoints: float = 0.3,
                     xyz_noise: float = 0.05) -> tuple[ModelArrays, np.ndarray]:
    """A model (see the module docstring) and the true points (n_points, 3)."""
    if camera not in ("PINHOLE", "OPENCV"):
        raise ValueError(f"camera must be PINHOLE or OPENCV, got {camera!r}")
    rng = np.random.default_rng(seed)
    V = int(n_images)
    angles = 2 * np.pi * np.arange(V) / V
    centres = np.column_stack([10 * np.cos(angles), 1.5 * np.sin(3 * angles), 10 * np.sin(angles)])
    poses = [_look_at(c) for c in centres]
    R = np.array([p[0] for p in poses])
    t = np.array([p[1] for p in poses])
    f = 800.0 + rng.uniform(-20, 20, V)
    params = []
    for v in range(V):
        base = (f[v], f[v] * 1.002, 512.0 + rng.uniform(-3, 3), 384.0 + rng.uniform(-3, 3))
        params.append(np.array(base + (OPENCV_DISTORTION if camera == "OPENCV" else ()), float))
    X = rng.normal(size=(n_points, 3))
    X *= (2.0 * rng.uniform(size=(n_points, 1)) ** (1 / 3)) / np.linalg.norm(X, axis=1, keepdims=True)
    lens = np.minimum(2 + rng.geometric(0.4, n_points) - 1, min(max_track, V))
    first = rng.integers(0, V, n_points)
    owner = np.repeat(np.arange(n_points), lens)
    step = np.arange(int(lens.sum())) - np.repeat(np.cumsum(lens) - lens, lens)
    img = (first[owner] + step) % V
    Xc = np.einsum("tij,tj->ti", R[img], X[owner]) + t[img]
    dist = np.array([p[4:8] if camera == "OPENCV" else np.zeros(4) for p in params])
    uv = distort_rows(Xc[:, :2] / Xc[:, 2:3], dist[img])
    P = np.array(params)
    xy = np.column_stack([P[img, 0] * uv[:, 0] + P[img, 2], P[img, 1] * uv[:, 1] + P[img, 3]])
    xy += noise_px * rng.normal(size=xy.shape)
    # keypoints per image: its observations (in point order) then unmatched ones
    n_extra = rng.poisson(extra_keypoints * np.bincount(img, minlength=V) + 1)
    extra_img = np.repeat(np.arange(V), n_extra)
    all_img = np.concatenate([img, extra_img])
    all_xy = np.concatenate([xy, np.column_stack([rng.uniform(0, 1024, len(extra_img)),
                                                  rng.uniform(0, 768, len(extra_img))])])
    all_pid = np.concatenate([owner + 1, np.full(len(extra_img), -1)])
    order = np.argsort(all_img, kind="stable")
    counts = np.bincount(all_img, minlength=V)
    kp_offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    rank = np.empty(len(order), np.int64)
    rank[order] = np.arange(len(order)) - kp_offsets[all_img[order]]
    arrays = ModelArrays(
        camera_ids=np.arange(1, V + 1, dtype=np.int64), camera_models=(camera,) * V,
        camera_width=np.full(V, 1024, np.int64), camera_height=np.full(V, 768, np.int64),
        camera_params=tuple(params), image_ids=np.arange(1, V + 1, dtype=np.int64),
        image_qvec=np.array([qvec_from_rotation(r) for r in R]), image_tvec=t, image_camera=np.arange(V),
        image_names=tuple(f"image_{v:04d}.jpg" for v in range(V)), kp_offsets=kp_offsets, kp_xy=all_xy[order],
        kp_point3D=all_pid[order].astype(np.int64), point_ids=np.arange(1, n_points + 1, dtype=np.int64),
        point_xyz=X + xyz_noise * rng.normal(size=X.shape),
        point_rgb=rng.integers(0, 256, (n_points, 3)).astype(np.uint8), point_error=np.full(n_points, 0.5),
        track_offsets=np.concatenate([[0], np.cumsum(lens)]).astype(np.int64), track_image=img.astype(np.int64),
        track_kp=rank[:len(img)])
    return arrays, X
