"""Polytope regions {y : ||B y + c||_inf <= 1} at any size: vertices by the O(m log m) angular
sweep against independent references (scipy's Qhull half-space intersection with a Chebyshev
centre from scipy's LP, analytic polygons), degenerate and empty sets, scale invariance, and
distances against dense boundary sampling."""
import time
import tracemalloc

import numpy as np
import pytest
from scipy.optimize import linprog
from scipy.spatial import HalfspaceIntersection

from tritools.model.regions import Polytope, polytope_vertices
from tritools.model.regions import polytope as polytope_module

RNG = np.random.default_rng(2024)


# ---------------------------------------------------------------- independent references
def chebyshev(B, c):
    """(centre, radius) of the largest disc in the polytope by scipy's LP (radius < 0: empty)."""
    n = np.linalg.norm(B, axis=1)
    A = np.vstack([np.c_[B, n], np.c_[-B, n]])
    b = np.concatenate([1 - c, 1 + c])
    res = linprog([0, 0, -1], A_ub=A, b_ub=b, bounds=[(None, None), (None, None), (None, 1e6)], method="highs")
    assert res.status == 0
    return res.x[:2], res.x[2]


def qhull_vertices(B, c):
    """Vertices by scipy.spatial.HalfspaceIntersection (Qhull), duplicates merged."""
    centre, radius = chebyshev(B, c)
    assert radius > 1e-6
    hs = np.vstack([np.c_[B, c - 1], np.c_[-B, -c - 1]])
    pts = HalfspaceIntersection(hs, centre).intersections
    scale = 1 + np.abs(pts).max()
    out = []
    for p in pts:
        if all(np.linalg.norm(p - q) > 1e-9 * scale for q in out):
            out.append(p)
    return np.array(out)


def assert_same_vertex_set(V, ref, tol):
    assert len(V) == len(ref), (len(V), len(ref))
    for v in V:
        assert np.min(np.linalg.norm(ref - v, axis=1)) <= tol
    for r in ref:
        assert np.min(np.linalg.norm(V - r, axis=1)) <= tol


def assert_ccw_convex(V):
    e = np.roll(V, -1, axis=0) - V
    f = np.roll(e, -1, axis=0)
    assert np.all(e[:, 0] * f[:, 1] - e[:, 1] * f[:, 0] > 0)


def random_slabs(m, spread=1.0):
    B = RNG.normal(size=(m, 2)) * RNG.uniform(0.1, 10.0, (m, 1))
    c = RNG.uniform(-1.5, 1.5, m) * spread
    return B, c


def rotation(th):
    return np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])


# ---------------------------------------------------------------- size
def circle_polygon(m):
    t = np.linspace(0, 2 * np.pi, m)
    return np.c_[np.cos(t), np.sin(t)], np.zeros(m)


def test_m1000_circle_polygon_is_fast_small_and_exact():
    B, c = circle_polygon(1000)
    tracemalloc.start()
    t0 = time.perf_counter()
    R = Polytope(B, c)
    elapsed = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert elapsed < 0.5, f"{elapsed:.3f} s"
    assert peak < 50e6, f"{peak / 1e6:.1f} MB"            # the pairwise method needed ~16 GB
    # analytic: the normals +-(cos t, sin t) at angles phi_k (t and t + pi, t = 0 and 2 pi coincide);
    # the vertex between phi_k and phi_k+1 is at angle (phi_k + phi_k+1)/2, radius 1/cos((phi_k+1 - phi_k)/2)
    t = np.linspace(0, 2 * np.pi, 1000)[:-1]
    phi = np.sort(np.concatenate([t, t + np.pi]) % (2 * np.pi))
    gap = np.diff(np.append(phi, phi[0] + 2 * np.pi))
    ang = phi + gap / 2
    ref = np.c_[np.cos(ang), np.sin(ang)] / np.cos(gap / 2)[:, None]
    V = R.vertices
    assert V.shape == (1998, 2)
    order = np.argsort(np.arctan2(ref[:, 1], ref[:, 0]))
    assert np.max(np.abs(V - ref[order])) < 1e-12
    assert_ccw_convex(V)
    assert np.linalg.norm(R.center) < 1e-12


def test_large_m_scales_near_linearly():
    B, c = circle_polygon(20_000)
    t0 = time.perf_counter()
    R = Polytope(B, c)
    assert time.perf_counter() - t0 < 5.0
    assert len(R.vertices) == 39_998
    P = 3 * RNG.normal(size=(200, 2))
    r = np.hypot(*P.T)
    # the polygon is within 1/cos(pi/39998) - 1 ~ 3e-9 of the unit disc
    assert np.allclose(R.distance(P), np.maximum(r - 1, 0), atol=5e-9)


def test_chunked_computations_do_not_change_results(monkeypatch):
    B, c = circle_polygon(300)
    R = Polytope(B, c)
    P = 2 * RNG.normal(size=(500, 2))
    d, C, inside = R.distance(P), R.closest_point(P), R.contains(P)
    monkeypatch.setattr(polytope_module, "POLYTOPE_CHUNK", 64)
    R2 = Polytope(B, c)
    assert np.array_equal(R2.vertices, R.vertices)
    assert np.array_equal(R2.contains(P), inside)
    assert np.allclose(R2.closest_point(P), C, rtol=0, atol=1e-15)
    assert np.allclose(R2.distance(P), d, rtol=0, atol=1e-15)


# ---------------------------------------------------------------- agreement with Qhull
@pytest.mark.parametrize("m", [2, 3, 4, 7, 15, 40, 200])
def test_random_polytopes_match_qhull(m):
    done = 0
    while done < 25:
        B, c = random_slabs(m, spread=RNG.uniform(0, 2))
        centre, radius = chebyshev(B, c)
        if radius < -1e-9:
            with pytest.raises(ValueError, match="empty"):
                Polytope(B, c)
            continue
        if radius < 1e-6:
            continue
        V = Polytope(B, c).vertices
        ref = qhull_vertices(B, c)
        assert_same_vertex_set(V, ref, 1e-9 * (1 + np.abs(ref).max()))
        assert_ccw_convex(V)
        # every vertex is feasible and lies on two boundary lines
        res = np.abs(V @ B.T + c)
        assert np.all(res <= 1 + 1e-9)
        assert np.all(np.sum(np.abs(res - 1) <= 1e-9, axis=1) >= 2)
        done += 1


def test_duplicate_parallel_and_zero_rows():
    for _ in range(30):
        m = int(RNG.integers(3, 9))
        ang = np.sort(RNG.uniform(0, np.pi, m))
        B = np.c_[np.cos(ang), np.sin(ang)] * RNG.uniform(0.5, 2, (m, 1))
        c = RNG.uniform(-0.5, 0.5, m)
        V = polytope_vertices(B, c)
        # the same slabs again, negated (|-(By + c)| = |By + c|), reordered, plus always-true zero rows
        B2 = np.vstack([B, B, -B, B[::-1], np.zeros((2, 2))])
        c2 = np.concatenate([c, c, -c, c[::-1], [0.3, -1.0]])
        V2 = polytope_vertices(B2, c2)
        assert V2.shape == V.shape and np.max(np.abs(V2 - V)) < 1e-12
        # parallel rows with other offsets: narrower slabs in the same directions
        B3 = np.vstack([B, 2 * B])
        c3 = np.concatenate([c, 2 * c + RNG.uniform(-0.3, 0.3, m)])
        if chebyshev(B3, c3)[1] > 1e-6:
            assert_same_vertex_set(polytope_vertices(B3, c3), qhull_vertices(B3, c3), 1e-9)


def test_near_parallel_duplicates():
    # the same line written with slightly different normals (rounding-level differences)
    B = np.array([[1.0, 0.0], [0.0, 1.0], [0.6, 0.8], [0.3, 0.4 + 1e-16], [0.6 * (1 + 1e-15), 0.8]])
    c = np.array([0.0, 0.0, 0.2, 0.1, 0.2])
    V = polytope_vertices(B, c)
    ref = qhull_vertices(B, c)
    assert_same_vertex_set(V, ref, 1e-9)


# ---------------------------------------------------------------- degenerate and thin sets
def test_touching_slabs_give_a_segment_in_any_orientation():
    for _ in range(200):
        th = RNG.uniform(0, 2 * np.pi)
        u, v = np.array([np.cos(th), np.sin(th)]), np.array([-np.sin(th), np.cos(th)])
        d, e = RNG.normal() * RNG.choice([1.0, 100.0, 1e4]), RNG.normal()
        L, a, b = RNG.uniform(0.1, 3, 3)
        # d - 2a <= u.y <= d  and  d <= u.y <= d + 2b  touch along u.y = d;  |v.y - e| <= L
        B = np.array([u / a, u / b, v / L])
        c = np.array([-(d - a) / a, -(d + b) / b, -e / L])
        V = Polytope(B, c).vertices
        ref = np.array([d * u + (e - L) * v, d * u + (e + L) * v])
        assert V.shape == (2, 2)
        err = min(np.abs(V - ref).max(), np.abs(V - ref[::-1]).max())
        assert err <= 1e-12 * (1 + np.abs(ref).max())


def test_polytope_reduced_to_a_point():
    # two pairs of touching slabs
    for _ in range(100):
        p = RNG.normal(size=2) * RNG.choice([1.0, 1e3])
        rows, cs = [], []
        for _ in range(2):
            th = RNG.uniform(0.2, np.pi - 0.2) + len(rows) * 0.1
            u = np.array([np.cos(th), np.sin(th)])
            a, b = RNG.uniform(0.1, 3, 2)
            rows += [u / a, u / b]
            cs += [-(u @ p - a) / a, -(u @ p + b) / b]
        if abs(rows[0][0] * rows[2][1] - rows[0][1] * rows[2][0]) < 0.1:
            continue
        R = Polytope(np.array(rows), np.array(cs))
        assert R.vertices.shape == (1, 2)
        assert np.abs(R.vertices[0] - p).max() <= 1e-11 * (1 + np.abs(p).max())
        assert R.distance(p + [3.0, 4.0]) == pytest.approx(5.0, rel=1e-9)
    # three lines through one point: y1 <= 1, y2 <= 1, y1 + y2 >= 2 (any rigid motion and scale)
    for _ in range(50):
        Q, s, t = rotation(RNG.uniform(0, 6.3)), RNG.uniform(0.5, 2), 10 * RNG.normal(size=2)
        B0, c0 = np.array([[1.0, 0], [0, 1], [0.5, 0.5]]), np.array([0, 0, -2.0])
        B = B0 @ Q.T / s
        V = polytope_vertices(B, c0 - B @ t)
        assert V.shape == (1, 2) and np.abs(V[0] - (s * Q @ [1.0, 1.0] + t)).max() < 1e-12 * 20


def test_thin_polygons():
    u = np.array([np.cos(0.3), np.sin(0.3)])
    # a polygon with interior keeps its width whatever its aspect (issue 24: thinning a 2 x 1e10 box to a
    # segment made distances wrong by the width); only a set without interior becomes a segment
    for w, count in [(1e-3, 4), (1e-6, 4), (1e-11, 4)]:
        # the unit box crossed by the slab |u.y - 0.1| <= w/2
        B = np.array([[1.0, 0.0], [0.0, 1.0], u / (w / 2)])
        c = np.array([0.0, 0.0, -0.1 / (w / 2)])
        V = polytope_vertices(B, c)
        assert len(V) == count
        # analytic: u.y = 0.1 +- w/2 meets y2 = +-1
        ys = [(0.1 + s * w / 2 - u[1] * y2) / u[0] for s in (-1, 1) for y2 in (-1, 1)]
        for v in V:
            assert abs(v[1]) == pytest.approx(1.0, abs=1e-12)
            assert min(abs(v[0] - y) for y in ys) < 1e-9
        if w >= 1e-3:
            assert_same_vertex_set(V, qhull_vertices(B, c), 1e-9)


def test_old_example_degenerate_segment_kept():
    B = np.array([[1.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    R = Polytope(B, [-1.0, -3.0, 0.0])
    assert R.vertices.tolist() == [[2.0, -1.0], [2.0, 1.0]]
    assert np.allclose(R.center, [2.0, 0.0])
    assert R.contains([2.0, 0.5]) and not R.contains([2.1, 0.5])


# ---------------------------------------------------------------- scale and position
@pytest.mark.parametrize("s", [1e-300, 1e-150, 1e-8, 1e8, 1e150, 1e300])
def test_vertices_scale_with_the_polygon(s):
    B, c = np.array([[1.0, 0.2], [0.3, -1.0], [0.7, 0.7]]), np.array([0.1, -0.2, 0.3])
    V = Polytope(B, c).vertices
    R = Polytope(B / s, c)                                # the same polygon scaled by s
    assert R.vertices.shape == V.shape
    assert np.max(np.abs(R.vertices / s - V)) < 1e-14
    assert np.allclose(R.center / s, Polytope(B, c).center, rtol=0, atol=1e-14)
    q = V[0] * 3.0
    assert R.distance(q * s) / s == pytest.approx(Polytope(B, c).distance(q), rel=1e-13)


def test_far_from_the_origin():
    box = Polytope.box([1e6, -2e6], [1e-3, 2e-3])
    assert np.allclose(box.vertices, [[1e6 - 1e-3, -2e6 - 2e-3], [1e6 + 1e-3, -2e6 - 2e-3],
                                      [1e6 + 1e-3, -2e6 + 2e-3], [1e6 - 1e-3, -2e6 + 2e-3]], rtol=0, atol=1e-9)
    big = Polytope.box([1e300, -1e300], [1e299, 1e299])
    assert big.distance([0.0, 0.0]) == pytest.approx(np.hypot(9e299, 9e299), rel=1e-12)
    flat = Polytope.box([0.0, 0.0], [1.0, 1e-200])       # bounded, not rank deficient: a 1e-200 thin box
    assert len(flat.vertices) == 2 and flat.distance([3.0, 0.0]) == pytest.approx(2.0)
    assert np.allclose(flat.closest_point([1e308, -1e308]), [1.0, 0.0], atol=1e-150)


# ---------------------------------------------------------------- distances
def test_distance_matches_dense_boundary_sampling_for_many_edges():
    B = random_slabs(60)[0]
    c = np.zeros(60)                                       # every slab contains 0
    R = Polytope(B, c)
    ref_V = qhull_vertices(B, c)
    ref_V = ref_V[np.argsort(np.arctan2(*(ref_V - ref_V.mean(0)).T[::-1]))]
    # dense samples of the boundary of the Qhull polygon
    t = np.linspace(0, 1, 4001)[:, None]
    samples = np.vstack([a + t * (b - a) for a, b in zip(ref_V, np.roll(ref_V, -1, axis=0))])
    P = 2.0 * RNG.normal(size=(300, 2))
    inside = np.all(np.abs(P @ B.T + c) <= 1, axis=1)
    ref = np.array([np.sqrt(np.min(np.sum((samples - p) ** 2, axis=1))) for p in P])
    ref[inside] = 0.0
    spacing = max(np.linalg.norm(b - a) for a, b in zip(ref_V, np.roll(ref_V, -1, axis=0))) / 4000
    d = R.distance(P)
    assert np.all(d <= ref + 1e-12) and np.all(ref - d <= spacing + 1e-12)
    assert np.array_equal(R.contains(P), inside)


# ---------------------------------------------------------------- errors
@pytest.mark.parametrize("B,c,match", [
    ([[1.0, 0.0], [2.0, 0.0]], [0.0, 0.0], r"rank < 2 .*unbounded"),
    ([[1.0, 1.0], [-3.0, -3.0], [0.0, 0.0]], [0.0, 0.5, 0.0], r"rank < 2 .*unbounded"),
    ([[0.0, 0.0], [0.0, 0.0]], [0.0, 0.0], r"rank < 2 .*unbounded"),
    ([[1.0, 0.0], [0.0, 1.0], [1.0, 0.0]], [0.0, 0.0, 5.0], r"polytope .* is empty"),
    ([[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]], [0.0, 0.0, 1.5], r"row 2 of B is zero and \|c\[2\]\| = 1.5 > 1"),
    ([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]], [0.0, 0.0, 3.0 + 1e-9], r"empty"),
    ([[1.0, 0.0], [0.0, 1.0]], [0.0], r"c must have shape \(2,\) to match B"),
    ([[1.0, 0.0], [0.0, 1.0]], [0.0, np.inf], r"c must be finite"),
    ([[1.0, 0.0], [0.0, 1j]], [0.0, 0.0], r"B must be real numbers, got complex128"),
    ([[1.0, 0.0], [0.0, 1.0]], ["a", "b"], r"c must be real numbers, got str"),
])
def test_bad_polytopes(B, c, match):
    with pytest.raises(ValueError, match=match):
        Polytope(B, c)
    with pytest.raises(ValueError, match=match):
        polytope_vertices(B, c)


def test_touching_at_a_corner_is_not_empty():
    # y1 <= 1, y2 <= 1 (box |y| <= 1) and y1 + y2 >= 2: exactly the corner (1, 1)
    R = Polytope([[1.0, 0.0], [0.0, 1.0], [0.5, 0.5]], [0.0, 0.0, -2.0])
    assert R.vertices.tolist() == [[1.0, 1.0]]
