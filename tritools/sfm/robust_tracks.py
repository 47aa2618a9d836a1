"""Outlier observations out of a COLMAP model (``tritools colmap --robust``).

With ``robust`` (:class:`~tritools.sfm.pipeline.RetriangulationOptions`), every re-triangulated point keeps
only the observations its certified TLS estimate calls inliers: :func:`drop_observations` removes the others
from the track written to points3D, and :func:`rewrite_images` sets the POINT3D_ID of their keypoints to -1
(COLMAP's convention for a keypoint without a 3D point) once every chunk is done.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from ..io.colmap.arrays import ModelArrays, PointChunk
from ..io.colmap.binary import write_images_binary
from ..io.colmap.formats import model_files
from ..io.colmap.text_arrays import write_images_text

__all__ = ["drop_observations", "rewrite_images"]


def drop_observations(arrays: ModelArrays, chunk: PointChunk, keep: np.ndarray, removed: list) -> PointChunk:
    """The chunk with the observations where ``keep`` is False left out of the tracks; their global keypoint
    indices are appended to ``removed``."""
    keep = np.asarray(keep, bool)
    if keep.all():
        return chunk
    gone = ~keep
    removed.append(arrays.kp_offsets[chunk.track_image[gone]] + chunk.track_kp[gone])
    owner = np.repeat(np.arange(len(chunk)), chunk.track_lengths)
    lengths = np.bincount(owner[keep], minlength=len(chunk))
    offsets = np.concatenate([[0], np.cumsum(lengths)]).astype(chunk.track_offsets.dtype)
    return dataclasses.replace(chunk, track_offsets=offsets, track_image=chunk.track_image[keep],
                               track_kp=chunk.track_kp[keep])


def rewrite_images(arrays: ModelArrays, folder, fmt: str, removed_kp: np.ndarray) -> Path:
    """Write the images file of ``arrays`` into ``folder`` again, the keypoints ``removed_kp`` (global indices)
    without a 3D point (POINT3D_ID -1)."""
    kp = arrays.kp_point3D.copy()
    kp[np.asarray(removed_kp, np.int64)] = -1
    fields = {k: getattr(arrays, k) for k in arrays.__dataclass_fields__}
    fields["kp_point3D"] = kp
    path = Path(folder) / model_files(fmt)[1]
    (write_images_binary if fmt == "bin" else write_images_text)(ModelArrays(**fields), path)
    return path
