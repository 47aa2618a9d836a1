"""Polytope.closest_point of one point (the scalar twin ``polygon_distance.closest_on_boundary_one``) equals the
vectorised search bit for bit, on polygons, segments and single points (touching slabs) at scales 1e-4..1e4, with
points near, far and beyond 1e150 polygon sizes; the containment test gives the same bits in any batch; and the
closest point is no farther than any boundary sample (an independent check)."""
import numpy as np
import pytest

from tritools.model.regions import Polytope


def _polygons(rng, count):
    out = []
    while len(out) < count:
        m = int(rng.integers(3, 9))
        ang = np.sort(rng.uniform(0, 2 * np.pi, m))
        B = np.c_[np.cos(ang), np.sin(ang)] * rng.uniform(0.1, 3, (m, 1)) * 10.0 ** rng.integers(-4, 5)
        try:
            out.append(Polytope(B, rng.normal(size=m)))
        except ValueError:
            continue
    return out


def _degenerate():
    segment = Polytope(np.array([[1.0, 0.0], [0.0, 1.0], [0.0, 1.0]]), np.array([0.0, -1.0, 1.0]))   # y2 = 0
    point = Polytope(np.array([[1.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.0, 1.0]]),
                     np.array([-1.0, 1.0, -1.0, 1.0]))                                                 # y = (0, 0)
    return [segment, point]


def _queries(poly, rng):
    size = float(np.max(np.abs(poly.vertices - poly.vertices.mean(axis=0)))) or 1.0
    ctr = poly.vertices.mean(axis=0)
    qs = [ctr + size * rng.normal(size=2) * 10.0 ** rng.integers(-3, 7) for _ in range(25)]
    qs += [poly.vertices[0], poly.vertices[0] * (1 + 1e-15), ctr + 1e200 * rng.normal(size=2)]
    return qs


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_one_point_equals_the_vectorised_search(seed):
    rng = np.random.default_rng(seed)
    polys = _polygons(rng, 40) + _degenerate()
    assert len(_degenerate()[0].vertices) == 2 and len(_degenerate()[1].vertices) == 1
    for poly in polys:
        qs = _queries(poly, rng)
        many = poly.closest_point(np.array(qs))
        for q, ref in zip(qs, many):
            one = poly.closest_point(q)
            assert one.shape == (2,) and np.array_equal(one, ref), (poly.B, q, one, ref)
            assert np.array_equal(one, poly.closest_point(q[None])[0])


def test_closest_point_is_no_farther_than_boundary_samples():
    rng = np.random.default_rng(7)
    for poly in _polygons(rng, 15) + _degenerate():
        V = poly.vertices
        E = np.roll(V, -1, axis=0) if len(V) > 2 else V[::-1]
        t = np.linspace(0.0, 1.0, 201)[:, None, None]
        samples = (V[None] + t * (E - V)[None]).reshape(-1, 2)
        for q in _queries(poly, rng)[:25]:
            c = poly.closest_point(q)
            d = np.hypot(*(q - c))
            scale = max(1.0, float(np.abs(q).max()))
            assert d <= np.min(np.hypot(*(samples - q).T)) + 1e-12 * scale
            if not poly.contains(q):
                assert np.all(np.abs(poly.B @ c + poly.c) <= 1.0 + 1e-9)
            else:
                assert np.array_equal(c, q)


def test_gamma_of_one_point_equals_the_stacked_loop():
    """geometry.gamma_validated of one point (the regions' one-point paths) equals its value in a stack of points to
    round-off (the projections' matrix products take shape-dependent kernels), with mixed regions and polygons."""
    from tritools.model.geometry import gamma_validated
    from tritools.scene import uncertain_problem

    P, R, X = uncertain_problem(8, seed=4, kinds="mixed")
    rng = np.random.default_rng(3)
    Xs = X + rng.normal(size=(12, 3)) * 0.3
    stacked = gamma_validated(Xs, P, R)
    one = np.array([gamma_validated(Xi[None], P, R)[0] for Xi in Xs])
    np.testing.assert_allclose(one, stacked, rtol=1e-12, atol=0)
    polys = [r if isinstance(r, Polytope) else Polytope.box(r.center, [1.0, 2.0]) for r in R]
    np.testing.assert_allclose(np.array([gamma_validated(Xi[None], P, polys)[0] for Xi in Xs]),
                               gamma_validated(Xs, P, polys), rtol=1e-12, atol=0)
