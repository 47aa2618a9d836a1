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

__all__ = ["drop_observations", "rewrite_images", "without_observations", "removed_observations"]


def drop_observations(arrays: ModelArrays, chunk: PointChunk, keep: np.ndarray, removed: list) -> PointChunk:
    """The chunk with the observations where ``keep`` is False left out of the tracks; their global keypoint
    indices are appended to ``removed``."""
    keep = np.asarray(keep, bool)
    if keep.all():
        return chunk
    removed.append(arrays.kp_offsets[chunk.track_image[~keep]] + chunk.track_kp[~keep])
    return dataclasses.replace(chunk, **_kept_tracks(chunk.track_offsets, chunk.track_image, chunk.track_kp, keep))


def _kept_tracks(offsets: np.ndarray, image: np.ndarray, kp: np.ndarray, keep: np.ndarray) -> dict:
    """The CSR tracks (``track_offsets``, ``track_image``, ``track_kp``) with the elements where ``keep`` is False
    left out."""
    n = len(offsets) - 1
    owner = np.repeat(np.arange(n), np.diff(offsets))
    lengths = np.bincount(owner[keep], minlength=n)
    return dict(track_offsets=np.concatenate([[0], np.cumsum(lengths)]).astype(offsets.dtype),
                track_image=image[keep], track_kp=kp[keep])


def _unlinked(arrays: ModelArrays, removed_kp: np.ndarray, **fields) -> ModelArrays:
    """``arrays`` with the keypoints ``removed_kp`` (global indices) without a 3D point (POINT3D_ID -1) and the
    other ``fields`` replaced."""
    kp = arrays.kp_point3D.copy()
    kp[np.asarray(removed_kp, np.int64)] = -1
    out = {k: getattr(arrays, k) for k in arrays.__dataclass_fields__}
    out.update(fields, kp_point3D=kp)
    return ModelArrays(**out)


def rewrite_images(arrays: ModelArrays, folder, fmt: str, removed_kp: np.ndarray) -> Path:
    """Write the images file of ``arrays`` into ``folder`` again, the keypoints ``removed_kp`` (global indices)
    without a 3D point (POINT3D_ID -1)."""
    path = Path(folder) / model_files(fmt)[1]
    (write_images_binary if fmt == "bin" else write_images_text)(_unlinked(arrays, removed_kp), path)
    return path


def without_observations(arrays: ModelArrays, keep: np.ndarray) -> ModelArrays:
    """The model in memory with the track elements where ``keep`` (one flag per observation, the arrays'
    track order) is False left out of their tracks and their keypoints unlinked (POINT3D_ID -1): what
    :func:`drop_observations` and :func:`rewrite_images` write to disk."""
    keep = np.asarray(keep, bool)
    if keep.all():
        return arrays
    removed = arrays.kp_offsets[arrays.track_image[~keep]] + arrays.track_kp[~keep]
    return _unlinked(arrays, removed, **_kept_tracks(arrays.track_offsets, arrays.track_image, arrays.track_kp, keep))


def removed_observations(before: ModelArrays, after: ModelArrays) -> list[tuple[int, int]]:
    """(image id, keypoint index) of every keypoint linked to a 3D point in ``before`` and not in ``after``."""
    gone = np.nonzero((before.kp_point3D != -1) & (after.kp_point3D == -1))[0]
    img = np.searchsorted(before.kp_offsets, gone, side="right") - 1
    return [(int(before.image_ids[i]), int(g - before.kp_offsets[i])) for i, g in zip(img, gone)]
