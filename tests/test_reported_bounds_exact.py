"""gamma_UB is never below the exact cost of the float data at the returned X (review 10): batches of mixed point /
disc problems in georeferenced worlds (the vectorised ellipse path reported plain projections, which cancel there:
a certificate with gamma_UB 8.6% below the exact cost), and large discs whose border passes near a projection
close to the image origin (the disc distance's round-off is relative to ||u - c||, not to |u|).  The exact cost is
evaluated in 60-digit decimal arithmetic of the float data (rho = sqrt(D_00) exactly)."""
from decimal import Decimal, localcontext

import numpy as np
import pytest

import tritools
from tritools.model.regions import Ellipse, Point
from tritools.scene import random_cameras


def _exact_gamma(cams, regions, X) -> Decimal:
    """sqrt(sum_i d_i(X)^2 / 2N) of the float data, in decimal arithmetic of 60 digits."""
    with localcontext() as ctx:
        ctx.prec = 60
        Xh = [Decimal(float(v)) for v in X] + [Decimal(1)]
        total = Decimal(0)
        for P, r in zip(np.asarray(cams, float), regions):
            h = [sum(Decimal(float(P[k, j])) * Xh[j] for j in range(4)) for k in range(3)]
            c = [Decimal(float(v)) for v in r.center]
            d = ((h[0] / h[2] - c[0]) ** 2 + (h[1] / h[2] - c[1]) ** 2).sqrt()
            if not isinstance(r, Point):
                d = max(Decimal(0), d - Decimal(float(r.D[0, 0])).sqrt())
            total += d * d
        return (total / (2 * len(regions))).sqrt()


def _georeferenced_mixed(seed):
    rng = np.random.default_rng(seed)
    N = int(rng.integers(2, 6))
    focal = 10 ** rng.uniform(0, 4)
    cams = random_cameras(N, rng, focal=focal, image_size=(640.0, 480.0), radius=10 ** rng.uniform(0, 2))
    off = rng.normal(size=3) * 10 ** rng.uniform(4, 7)
    T = np.eye(4)
    T[:3, 3] = -off
    cams = np.array([P @ T for P in cams])
    X = rng.normal(size=3) + off
    h = np.einsum("nij,j->ni", cams, np.append(X, 1.0))
    x = h[:, :2] / h[:, 2:] + rng.normal(size=(N, 2)) * focal * 10 ** rng.uniform(-9, -6)
    regions = [Point(x[i]) if i % 2 == 0 else Ellipse(x[i], np.eye(2) * (focal * 10 ** rng.uniform(-10, -7)) ** 2)
               for i in range(N)]
    return cams, regions


def test_batch_of_georeferenced_mixed_regions_bounds_the_exact_cost():
    problems = [_georeferenced_mixed(seed) for seed in (10032, 10044, 10059, 10062, 10065, 10068, 10071, 10074)]
    results = tritools.triangulate_many(problems)
    certified = 0
    for (cams, regions), r in zip(problems, results):
        assert r.X is not None and r.gamma_ub is not None
        exact = _exact_gamma(cams, regions, r.X)
        assert Decimal(r.gamma_ub) >= exact, (r.gamma_ub, exact)
        if r.optimal:
            certified += 1
            assert Decimal(r.gamma_lb) <= exact
    assert certified >= 4


@pytest.mark.parametrize("seed", [0, 2, 5, 11])
def test_large_discs_far_from_their_centres_bound_the_exact_cost(seed):
    """Two observed points and a disc of radius 1e5-2e6 px whose border passes 1e-7..1e-4 px from the projection
    of the point, which lies near the image origin (|u| ~ 1e-3 px << ||u - c||)."""
    rng = np.random.default_rng(seed)
    cams = random_cameras(3, rng, image_size=(2.0, 2.0), focal=1000.0)
    cams[:, 0] -= cams[:, 2]
    cams[:, 1] -= cams[:, 2]                                    # principal point at the image origin
    X0 = rng.normal(size=3) * 1e-3
    h = np.einsum("nij,j->ni", cams, np.append(X0, 1.0))
    u = h[:, :2] / h[:, 2:]
    regions = [Point(u[0] + rng.normal(size=2) * 1e-6), Point(u[1] + rng.normal(size=2) * 1e-6)]
    angle = rng.uniform(0, 2 * np.pi)
    c = u[2] + 10 ** rng.uniform(5, 6.3) * np.array([np.cos(angle), np.sin(angle)])
    rho = float(np.linalg.norm(u[2] - c) - 10 ** rng.uniform(-7, -4))
    regions.append(Ellipse(c, np.eye(2) * rho * rho))
    for r in (tritools.triangulate(cams, regions, time_limit=0.5),
              tritools.triangulate_many([(cams, regions)], time_limit=0.5)[0]):
        assert r.X is not None
        exact = _exact_gamma(cams, regions, r.X)
        assert Decimal(r.gamma_ub) >= exact, (r.gamma_ub, exact)
        if r.gamma_lb is not None:
            assert Decimal(r.gamma_lb) <= Decimal(r.gamma_ub)
