"""The point-to-ellipse closest point (Eberly's 1-D root, safeguarded Newton since wave 19): the scalar and the
vectorised twins equal bit for bit, and the root that of an independent bisection to an ulp."""
from __future__ import annotations

import math

import numpy as np

from tritools.model.regions.ellipse import _ellipse_closest_local, ellipse_closest_scalar


def _bisection(e0, e1, y0, y1):
    """Eberly's bisection on u = s + 1 to full precision (the reference; first quadrant, y0, y1 > 0)."""
    z0, z1 = y0 / e0, y1 / e1
    g = z0 * z0 + z1 * z1 - 1.0
    if g == 0:
        return y0, y1
    r0 = (e0 / e1) ** 2
    n0, rm1 = r0 * z0, r0 - 1.0
    lo, hi = z1, (1.0 if g < 0 else math.hypot(n0, z1))
    for _ in range(2000):
        u = 0.5 * (lo + hi)
        G = (n0 / (u + rm1)) ** 2 + (z1 / u) ** 2 - 1.0
        if G > 0:
            lo = u
        elif G < 0:
            hi = u
        else:
            break
        if hi - lo <= 2 * np.finfo(float).eps * hi:
            break
    u = 0.5 * (lo + hi)
    return r0 * y0 / (u + rm1), y1 / u


def _cases(rng, n):
    for _ in range(n):
        e1 = 10 ** rng.uniform(-3, 3)
        e0 = e1 * 10 ** rng.uniform(0, 4)
        s = 10 ** rng.uniform(-6, 2)
        yield e0, e1, s


def test_scalar_root_matches_bisection():
    rng = np.random.default_rng(3)
    for e0, e1, s in _cases(rng, 3000):
        y0 = abs(rng.normal()) * e0 * s * rng.choice([1, 1e-6, 1e-12])
        y1 = abs(rng.normal()) * e1 * s * rng.choice([1, 1e-6, 1e-12])
        a = np.array(ellipse_closest_scalar(e0, e1, y0, y1))
        b = np.array(_bisection(e0, e1, y0, y1))
        assert np.all(np.abs(a - b) <= 4 * np.finfo(float).eps * e0), (e0, e1, y0, y1, a, b)
        assert abs((a[0] / e0) ** 2 + (a[1] / e1) ** 2 - 1.0) <= 1e-14


def test_vectorised_twin_equals_scalar():
    rng = np.random.default_rng(4)
    for e0, e1, s in _cases(rng, 200):
        Y = rng.normal(size=(40, 2)) * np.array([e0, e1]) * s * rng.choice([1, 1e-9], size=(40, 2))
        Y[0] = (0.0, Y[0, 1])                         # on an axis
        Y[1] = (Y[1, 0], 0.0)
        V = _ellipse_closest_local(e0, e1, Y)
        S = np.array([[(-a if y0 < 0 else a), (-b if y1 < 0 else b)]
                      for y0, y1 in Y for a, b in [ellipse_closest_scalar(e0, e1, abs(y0), abs(y1))]])
        assert np.array_equal(V, S)
