"""COLMAP sparse models: records and the text format (:mod:`.model`), camera models, distortion and
undistortion (:mod:`.camera_models`), pinhole projections and reprojection errors (:mod:`.projection`),
and conversion of 3x4 projection matrices / Oxford sequences to PINHOLE models (:mod:`.convert`)."""
from .camera_models import (CameraModel, UnsupportedCameraModelError, distort, intrinsics, pixels_from_camera,
                            undistort, undistorted_pixels)
from .convert import MAX_SKEW_PX, SkewError, model_from_oxford, model_from_projections
from .model import (Camera, Image, Model, ModelFormatError, Point3D, qvec_from_rotation, read_text_model,
                    rotation_from_qvec, write_text_model)
from .projection import projection_matrix, reprojection_error

__all__ = ["CameraModel", "UnsupportedCameraModelError", "distort", "intrinsics", "pixels_from_camera", "undistort",
           "undistorted_pixels", "MAX_SKEW_PX", "SkewError", "model_from_oxford", "model_from_projections", "Camera",
           "Image", "Model", "ModelFormatError", "Point3D", "qvec_from_rotation", "read_text_model",
           "rotation_from_qvec", "write_text_model", "projection_matrix", "reprojection_error"]
