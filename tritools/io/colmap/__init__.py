"""COLMAP sparse models: records and the text format (:mod:`.model`), the binary format
(:mod:`.binary`), the array representation of the fast path (:mod:`.arrays`), whole-model reading and
writing in either format with format detection and streaming (:mod:`.formats`), camera models,
distortion and undistortion (:mod:`.camera_models`), pinhole projections and reprojection errors
(:mod:`.projection`), and conversion of 3x4 projection matrices / Oxford sequences to PINHOLE
models (:mod:`.convert`), and ``pycolmap.Reconstruction`` objects in memory (:mod:`.pycolmap_bridge`)."""
from .arrays import ModelArrays, PointChunk
from .camera_models import (CameraModel, UnsupportedCameraModelError, distort, intrinsics, pixels_from_camera,
                            undistort, undistorted_pixels)
from .convert import MAX_SKEW_PX, SkewError, model_from_oxford, model_from_projections
from .formats import (ModelSource, ModelWriter, detect_format, open_model, read_binary_model, read_model,
                      read_model_arrays, write_binary_model, write_model, write_model_arrays)
from .model import (Camera, Image, Model, ModelFormatError, Point3D, qvec_from_rotation, read_text_model,
                    rotation_from_qvec, write_text_model)
from .projection import projection_matrix, reprojection_error
from .pycolmap_bridge import from_pycolmap, to_pycolmap

__all__ = ["ModelArrays", "PointChunk", "CameraModel", "UnsupportedCameraModelError", "distort", "intrinsics",
           "pixels_from_camera", "undistort", "undistorted_pixels", "MAX_SKEW_PX", "SkewError", "model_from_oxford",
           "model_from_projections", "ModelSource", "ModelWriter", "detect_format", "open_model",
           "read_binary_model", "read_model", "read_model_arrays", "write_binary_model", "write_model",
           "write_model_arrays", "Camera", "Image", "Model", "ModelFormatError", "Point3D", "qvec_from_rotation",
           "read_text_model", "rotation_from_qvec", "write_text_model", "projection_matrix", "reprojection_error",
           "from_pycolmap", "to_pycolmap"]
