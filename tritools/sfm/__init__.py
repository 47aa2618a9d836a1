"""Structure-from-motion workflows: certified re-triangulation of every 3D point of a COLMAP model
(:mod:`.retriangulate`) and its certificate sidecar.  Model formats live in :mod:`tritools.io.colmap`.

Workflow (see docs/colmap.md)::

    model = read_text_model("sparse/0")                       # tritools.io.colmap
    new_model, report = retriangulate(model, method="corollary1", path="auto")
    write_text_model(new_model, "sparse_certified")           # COLMAP-readable
    write_certificates(report, "sparse_certified")            # points3D_certificates.txt
"""
from .retriangulate import (CERTIFICATES_FILE, PointCertificate, RetriangulationReport, read_certificates,
                            retriangulate, write_certificates)

__all__ = ["CERTIFICATES_FILE", "PointCertificate", "RetriangulationReport", "read_certificates", "retriangulate",
           "write_certificates"]
