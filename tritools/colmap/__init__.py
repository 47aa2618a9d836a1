"""COLMAP text models: read/write, camera models, certified re-triangulation of every point.

Workflow (see docs/colmap.md)::

    model = read_text_model("sparse/0")                       # cameras.txt, images.txt, points3D.txt
    new_model, report = retriangulate(model, method="corollary1", path="auto")
    write_text_model(new_model, "sparse_certified")           # COLMAP-readable
    write_certificates(report, "sparse_certified")            # points3D_certificates.txt

Modules: :mod:`.model` (dataclasses, text format), :mod:`.camera_models` (K, distortion,
undistortion), :mod:`.retriangulate` (certificates, sidecar), :mod:`.convert` (3x4 projection
matrices / Oxford sequences -> PINHOLE model).
"""
from .camera_models import (CameraModel, UnsupportedCameraModelError, distort, intrinsics, pixels_from_camera,
                            undistort, undistorted_pixels)
from .convert import MAX_SKEW_PX, SkewError, model_from_oxford, model_from_projections
from .model import (Camera, Image, Model, ModelFormatError, Point3D, qvec_from_rotation, read_text_model,
                    rotation_from_qvec, write_text_model)
from .retriangulate import (CERTIFICATES_FILE, PointCertificate, RetriangulationReport, projection_matrix,
                            read_certificates, reprojection_error, retriangulate, write_certificates)

__all__ = ["CameraModel", "UnsupportedCameraModelError", "distort", "intrinsics", "pixels_from_camera", "undistort",
           "undistorted_pixels", "MAX_SKEW_PX", "SkewError", "model_from_oxford", "model_from_projections", "Camera",
           "Image", "Model", "ModelFormatError", "Point3D", "qvec_from_rotation", "read_text_model",
           "rotation_from_qvec", "write_text_model", "CERTIFICATES_FILE", "PointCertificate",
           "RetriangulationReport", "projection_matrix", "read_certificates", "reprojection_error", "retriangulate",
           "write_certificates"]
