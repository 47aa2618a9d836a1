"""The one input boundary for regions: :func:`as_regions` (and :func:`as_region` for one).

Accepted per view: a :class:`~.base.Region`, its :meth:`~.base.Region.to_dict` mapping, or a
2-vector of real numbers (a :class:`~.point.Point`); for all views at once, also a numeric
array of shape (N, 2) (N point regions, as the image points of ``cv2.triangulatePoints``).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike

from .base import Region, as_vector, real_array
from .point import Point

__all__ = ["as_region", "as_regions"]

_EXPECTED = "expected a Region, a to_dict mapping or a 2-vector of real numbers"


def as_region(obj, name: str = "region") -> Region:
    """Coerce one region: a :class:`Region` (returned as is), a :meth:`Region.to_dict`
    mapping, or a 2-vector of real numbers (a :class:`Point`).

    Parameters
    ----------
    obj : Region, Mapping or array_like (2,)
    name : str
        How error messages call ``obj`` (``as_regions`` passes ``"regions[i]"``).

    Raises
    ------
    ValueError
        ``obj`` is none of these, or its data are invalid; the message starts with ``name``.
    """
    if isinstance(obj, Region):
        return obj
    if isinstance(obj, Mapping):
        try:
            return Region.from_dict(obj)
        except (ValueError, TypeError) as exc:
            raise ValueError(f"{name}: {exc}") from exc
    if not isinstance(obj, (str, bytes)) and _shape(obj) == (2,):
        return Point(as_vector(obj, name))
    raise ValueError(f"{name}: cannot interpret {_short(obj)} as a region ({_EXPECTED})")


def _shape(obj) -> tuple | None:
    try:
        return np.shape(obj)
    except (TypeError, ValueError):
        return None


def _short(obj, limit: int = 60) -> str:
    text = repr(obj)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def as_regions(regions: Sequence | ArrayLike, n_views: int | None = None) -> tuple[Region, ...]:
    """Coerce the regions of all views: a sequence whose entries :func:`as_region` accepts
    (Regions, ``to_dict`` mappings, 2-vectors), or a numeric array of shape (N, 2) (N
    :class:`Point` regions).  This is the coercion used wherever regions enter the library.

    Parameters
    ----------
    regions : sequence or array_like (N, 2)
    n_views : int, optional
        The number of cameras; the count is checked when given.

    Returns
    -------
    tuple of Region

    Raises
    ------
    ValueError
        Not a sequence; an entry that cannot be read (the message names it, ``regions[3]: ...``);
        an array of another shape, not real, or not finite; ``len != n_views``.
    """
    iterable = hasattr(regions, "__iter__") or hasattr(regions, "__array__")
    if isinstance(regions, (Region, Mapping, str, bytes)) or not iterable:
        raise ValueError(f"regions must be a sequence with one region per view, got {type(regions).__name__}")
    if _is_array(regions):
        out = _points_from_array(regions)
    else:
        out = tuple(as_region(r, f"regions[{k}]") for k, r in enumerate(regions))
    if n_views is not None and len(out) != n_views:
        raise ValueError(f"regions: expected one region per camera ({n_views}), got {len(out)} "
                         f"(there must be one region per view)")
    return out


def _is_array(regions) -> bool:
    """A numeric array (not a list, not an object array holding Region instances)."""
    if isinstance(regions, (list, tuple)):
        return False
    if isinstance(regions, np.ndarray):
        return regions.dtype.kind != "O"
    return hasattr(regions, "__array__")


def _points_from_array(regions) -> tuple[Region, ...]:
    X = real_array(regions, "regions")
    if X.ndim != 2 or X.shape[1] != 2:
        raise ValueError(f"regions given as an array must have shape (N, 2), one image point per view, "
                         f"got shape {X.shape}")
    bad = np.flatnonzero(~np.all(np.isfinite(X), axis=1))
    if bad.size:
        k = int(bad[0])
        raise ValueError(f"regions[{k}] must be finite (no NaN/inf), got {X[k].tolist()}")
    return Point.from_checked_rows(X)           # (X: a new float64 array, every entry checked finite above)
