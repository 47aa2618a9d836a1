"""Independent reference for uncertain regions: an attained RMS reprojection residual (an upper bound of gamma*).

Regions are described by *specs* -- their own parametrisations, written from the regions' definitions, not
from tritools' polynomial models or distance code:

* ``("point", c)``: y = c;
* ``("segment", c, d)``: y = c + t d, |t| <= 1;
* ``("ellipse", c, L)`` / ``("border", c, L)``: y = c + L r (cos a, sin a), 0 <= r <= 1 (r = 1 on the border),
  for the ellipse (y - c)^T D^{-1} (y - c) <= 1 with D = L L^T;
* ``("box", c, h)``: y = c + h * u, |u_k| <= 1;
* ``("parallelogram", y0, M)``: y = y0 + M u, |u_k| <= 1 (the polytope ||B y + c||_inf <= 1 with a 2 x 2 B:
  M = B^{-1}, y0 = -B^{-1} c).

:func:`region_reference` minimises the residual over (X, parameters) by bounded least squares from several
starts; every value it returns is attained at a feasible point.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from tritools import Ellipse, EllipseBorder, Point, Polytope, Segment

__all__ = ["region_and_spec", "region_reference", "spec_of"]


def spec_of(region) -> tuple:
    """The spec of a tritools region from its public fields (points, segments, ellipses, borders and 2-row
    polytopes)."""
    if isinstance(region, Point):
        return ("point", np.asarray(region.x, float))
    if isinstance(region, Segment):
        return ("segment", np.asarray(region.center_, float), np.asarray(region.direction, float))
    if isinstance(region, (Ellipse, EllipseBorder)):
        kind = "border" if isinstance(region, EllipseBorder) else "ellipse"
        return (kind, np.asarray(region.center, float), np.linalg.cholesky(np.asarray(region.D, float)))
    if isinstance(region, Polytope) and np.asarray(region.B).shape == (2, 2):
        M = np.linalg.inv(np.asarray(region.B, float))
        return ("parallelogram", -M @ np.asarray(region.c, float), M)
    raise TypeError(f"no reference parametrisation for {type(region).__name__}")


def region_and_spec(kind, c, rng):
    """(region, spec) with spec the parametrisation used by the reference below."""
    if kind == "point":
        return Point(c), ("point", c)
    if kind == "segment":
        d = rng.normal(scale=4.0, size=2)
        return Segment(c, d), ("segment", c, d)
    if kind in ("ellipse", "border"):
        A = rng.normal(size=(2, 2))
        D = 4.0 * A @ A.T + np.eye(2)
        return (Ellipse if kind == "ellipse" else EllipseBorder)(c, D), (kind, c, np.linalg.cholesky(D))
    h = np.abs(rng.normal(scale=2.0, size=2)) + 0.5
    return Polytope.box(c, h), ("box", c, h)


def region_reference(cams, specs, starts, rng):
    """min over (X, region parameters) of the RMS reprojection residual, by bounded least squares from each
    start: y = c (point), c + t d with |t| <= 1 (segment), c + L r (cos a, sin a) with 0 <= r <= 1 (ellipse,
    r = 1 on its border; D = L L^T), c + h * u with |u_k| <= 1 (box).  Every value is attained at a feasible
    point: an upper bound on gamma*."""
    lo, hi = [-np.inf] * 3, [np.inf] * 3
    box = {"point": ([], []), "segment": ([-1], [1]), "ellipse": ([0, -np.inf], [1, np.inf]),
           "border": ([-np.inf], [np.inf]), "box": ([-1, -1], [1, 1]), "parallelogram": ([-1, -1], [1, 1])}
    for s in specs:
        lo += box[s[0]][0]
        hi += box[s[0]][1]

    def points(p):
        out, j = [], 0
        for s in specs:
            kind = s[0]
            if kind == "point":
                out.append(s[1])
            elif kind == "segment":
                out.append(s[1] + p[j] * s[2])
                j += 1
            elif kind == "ellipse":
                out.append(s[1] + s[2] @ (p[j] * np.array([np.cos(p[j + 1]), np.sin(p[j + 1])])))
                j += 2
            elif kind == "border":
                out.append(s[1] + s[2] @ np.array([np.cos(p[j]), np.sin(p[j])]))
                j += 1
            elif kind == "parallelogram":
                out.append(s[1] + s[2] @ p[j:j + 2])
                j += 2
            else:
                out.append(s[1] + s[2] * p[j:j + 2])
                j += 2
        return np.array(out)

    def residuals(z):
        h = cams @ np.append(z[:3], 1.0)
        return (h[:, :2] / h[:, 2:] - points(z[3:])).ravel()

    best = np.inf
    for X0 in starts:
        for _ in range(3):
            p0 = np.array([rng.uniform(0.1, 0.9) if (a == 0 and b == 1) else rng.uniform(-0.9, 0.9)
                           for a, b in zip(lo[3:], hi[3:])])
            try:
                r = least_squares(residuals, np.concatenate([X0, p0]), bounds=(lo, hi), xtol=1e-15, ftol=1e-15,
                                  gtol=1e-15, max_nfev=600)
            except ValueError:
                continue
            if np.all(np.isfinite(r.fun)):
                best = min(best, float(np.sqrt(np.mean(r.fun ** 2))))
    return best


