"""Projections of a COLMAP model: pinhole matrices P = K [R | t] and COLMAP's reprojection error."""
from __future__ import annotations

import numpy as np

from .camera_models import intrinsics, pixels_from_camera
from .model import Model

__all__ = ["projection_matrix", "reprojection_error"]


def projection_matrix(model: Model, image_id: int) -> np.ndarray:
    """P = K [R | t] of an image (pinhole part of its camera; see camera_models)."""
    im = model.images[image_id]
    cam = model.cameras[im.camera_id]
    return intrinsics(cam.model, cam.params) @ im.cam_from_world


def reprojection_error(model: Model, xyz, track) -> float:
    """COLMAP's error: mean over the track of |pi_i(X) - x_i| (pixels, full camera model)."""
    errs = []
    for image_id, idx in track:
        im = model.images[image_id]
        cam = model.cameras[im.camera_id]
        Xc = im.cam_from_world @ np.append(np.asarray(xyz, float), 1.0)
        x = pixels_from_camera(cam.model, cam.params, Xc)[0]
        errs.append(float(np.hypot(*(x - np.array(im.points2D[idx][:2])))))
    return float(np.mean(errs)) if errs else 0.0
