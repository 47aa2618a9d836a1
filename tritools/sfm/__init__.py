"""Structure-from-motion workflows: certified re-triangulation of every 3D point of a COLMAP model,
binary or text, and its certificate sidecar.  Model formats live in :mod:`tritools.io.colmap`.

* :func:`retriangulate` (a :class:`~tritools.io.colmap.Model` or a ``pycolmap.Reconstruction``, returned
  as the same type) and :func:`retriangulate_arrays` (a :class:`~tritools.io.colmap.ModelArrays`): in memory;
* :func:`retriangulate_folder`: folder to folder, streaming in chunks, written atomically;
* :func:`certify_stack`: the single call into the solver (stacks of tracks of equal length);
* :func:`write_certificates` / :func:`read_certificates`: the sidecar ``points3D_certificates.txt``.

Workflow (see docs/colmap.md)::

    result = retriangulate_folder("sparse/0", "sparse_certified")          # binary or text model
    model = read_model("sparse/0")                                         # tritools.io.colmap
    new_model, report = retriangulate(model, method="corollary1", path="auto")
"""
from .certificates import CERTIFICATES_FILE, CertificateWriter, read_certificates, write_certificates
from .certify import CertifyOptions, StackResult, certify_stack
from .folder import FolderResult, OutputError, atomic_directory, retriangulate_folder
from .pipeline import (BEHIND_CHOICES, DEFAULT_MAX_TRACK_LENGTH, CameraError, OptionError, RetriangulationOptions,
                       prepare_geometry, process_chunk)
from .retriangulate import PointCertificate, RetriangulationReport, retriangulate, retriangulate_arrays

__all__ = ["CERTIFICATES_FILE", "CertificateWriter", "read_certificates", "write_certificates", "CertifyOptions",
           "StackResult", "certify_stack", "FolderResult", "OutputError", "atomic_directory", "retriangulate_folder",
           "BEHIND_CHOICES", "DEFAULT_MAX_TRACK_LENGTH", "CameraError", "OptionError", "RetriangulationOptions",
           "prepare_geometry", "process_chunk", "PointCertificate", "RetriangulationReport", "retriangulate",
           "retriangulate_arrays"]
