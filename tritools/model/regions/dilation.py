"""Dilation of a region by r pixels, from its conic form (:meth:`~.base.Region.conic_form`).

``dilate(R, r)`` is a region holding every point within ``r`` of ``R`` (an outer bound of the
Minkowski sum ``R + B(0, r)``; exact for a point), of the same conic kinds, so the certified
uncertainty (:mod:`tritools.uncertain`) widens its per-view sets without knowing the region type:

=================  ==========================================================================
conic form         dilated by r (every length times ``1 + 1e-12`` against round-off)
=================  ==========================================================================
POINT x^           the disc of radius r around x^ (an ELLIPSE, exact)
SEGMENT x^, d      the rectangle ``||d|| + r`` along d, ``r`` across (a POLYTOPE)
POLYTOPE B, c      each slab widened by ``r ||B_k||``: ``B / f_k``, ``c / f_k``, ``f_k = 1 + r ||B_k||``
ELLIPSE D          the coaxial ellipse of semi-axes ``sqrt((1 + t) a_k^2 + (1 + 1/t) r^2)``
=================  ==========================================================================

The ellipse rule: the support function of ``R + B(0, r)`` is ``h(u) + r`` and
``(h + r)^2 <= (1 + t) h^2 + (1 + 1/t) r^2`` for any ``t > 0``; the ellipse of least area among
``t = r / a_1, r / a_2, r / sqrt(a_1 a_2)`` is kept (exact for a circle).  An ellipse border is
dilated through its filled ellipse (its conic form, flagged ``convexified``).
"""
from __future__ import annotations

import numpy as np

from .base import Region
from .ellipse import Ellipse
from .forms import ConeKind, ConicForm, conic_form_of
from .polytope import Polytope
from .shapes import shape_fields

__all__ = ["dilate", "DILATION_GROW"]

#: relative enlargement of every dilated length (round-off of the constructions below).
DILATION_GROW = 1.0 + 1e-12


def dilate(region: Region, r: float) -> Region:
    """A region containing every point within ``r`` (>= 0) of ``region`` (module docstring); ``region``
    itself when ``r == 0``.

    Raises
    ------
    TypeError
        The region type declares no :meth:`~.base.Region.conic_form`.
    """
    if r == 0:
        return region
    form = conic_form_of(region)
    if form.kind == ConeKind.POINT:
        return Ellipse(form.center, (r * DILATION_GROW) ** 2 * np.eye(2))
    if form.kind == ConeKind.ELLIPSE:
        return _dilate_ellipse(form, r)
    if form.kind == ConeKind.POLYTOPE:
        f = (1.0 + r * np.linalg.norm(form.B, axis=1)) * DILATION_GROW + 1e-12 * np.abs(form.c)
        return Polytope(form.B / f[:, None], form.c / f)
    return _dilate_segment(form, r)


def _dilate_ellipse(form: ConicForm, r: float) -> Ellipse:
    """The coaxial ellipse of the module docstring (axes from :func:`~.shapes.shape_fields`, largest first: exact to
    round-off for thin ellipses, where an eigensolver's minor axis is off by ~eps lam_max)."""
    _, a, Q, _, _ = shape_fields(np.asarray(form.D, float)[None])
    a, Q = a[0], Q[0]
    best = None
    for t in (r / a[0], r / a[1], r / np.sqrt(a[0] * a[1])):
        ax = np.sqrt((1 + t) * a ** 2 + (1 + 1 / t) * r * r)
        if best is None or ax[0] * ax[1] < best[0] * best[1]:
            best = ax
    axes = best * DILATION_GROW
    return Ellipse(form.center, (Q * axes ** 2) @ Q.T)


def _dilate_segment(form: ConicForm, r: float) -> Polytope:
    """The rectangle ``||d|| + r`` along the direction d, ``r`` across, around the centre."""
    d = np.asarray(form.direction, float)
    s = float(np.max(np.abs(d)))
    u = d / s                                       # (scaled first: a norm of 1e-200 or 1e200 under/overflows)
    nd = s * float(np.linalg.norm(u))
    u = u / float(np.linalg.norm(u))
    n = np.array([-u[1], u[0]])
    half = np.array([nd + r, r]) * DILATION_GROW
    B = np.array([u / half[0], n / half[1]])
    return Polytope(B, -B @ form.center)
