"""The caller's estimate is only the reference of ``max_distance`` (review 26b F1/F5): the solvers are centred on the
problem's own start (the DLT of the region centres), so an estimate away from a tiny set (noise-free points, sub-pixel
discs), at a camera centre, or 5e6 away neither turns S into ``empty`` nor loosens its bounds.  A Farkas verdict is
local (it excludes the points within its reach of the centre): a point found in S refutes it.

Reference: the true point X, in S by construction, checked in exact rational arithmetic against the discs."""
from fractions import Fraction

import numpy as np
import pytest

import tritools
from tests.test_uncertainty import look_at

CAMS = np.array([look_at(np.array(c)) for c in ([-1.0, 0.0, -5.0], [1.0, 0.2, -5.0], [0.0, 1.0, -5.0])])


def _in_discs_exact(cams, centres, radius, X) -> bool:
    """X in every disc |Phi(X, P_i) - x_i| <= r, in front, in exact rational arithmetic on the float data."""
    Xh = [Fraction(float(v)) for v in X] + [Fraction(1)]
    for P, x in zip(cams, centres):
        h = [sum(Fraction(float(P[r, k])) * Xh[k] for k in range(4)) for r in range(3)]
        sign = 1 if np.linalg.det(P[:, :3]) > 0 else -1
        if sign * h[2] <= 0:
            return False
        d2 = (h[0] / h[2] - Fraction(float(x[0]))) ** 2 + (h[1] / h[2] - Fraction(float(x[1]))) ** 2
        if d2 > Fraction(radius) ** 2:
            return False
    return True


@pytest.mark.parametrize("seed", range(4))
def test_noise_free_points_with_a_distant_estimate_are_not_empty(seed):
    rng = np.random.default_rng(seed)
    X = rng.normal(size=3) * 0.3
    pts = [tritools.Point(tritools.project(X, P)) for P in CAMS]
    base = tritools.uncertainty(CAMS, pts)
    assert base.status == tritools.UncertaintyStatus.BOUNDED and base.contains(X)
    for E in (X + np.array([0.05, -0.05, 0.05]), X + 1.0, np.array([-1.0, 0.0, -5.0])):   # the last: camera 0's centre
        res = tritools.uncertainty(CAMS, pts, estimate=E)
        assert res.status == tritools.UncertaintyStatus.BOUNDED, (E, res.status)
        assert res.contains(X)
        assert np.array_equal(res.lo, base.lo) and np.array_equal(res.hi, base.hi)
        assert res.max_distance >= np.linalg.norm(X - E)


@pytest.mark.parametrize("radius", [1e-6, 1e-9, 1e-12])
def test_tiny_discs_with_the_estimate_at_a_camera_centre_are_not_empty(radius):
    X = np.array([0.1, -0.2, 0.3])
    x = np.array([tritools.project(X, P) for P in CAMS])
    assert _in_discs_exact(CAMS, x, radius, X)
    regions = [tritools.Ellipse.circle(xi, radius) for xi in x]
    for E in (np.array([-1.0, 0.0, -5.0]), X + np.array([1.0, 0.0, 0.0])):
        res = tritools.uncertainty(CAMS, regions, estimate=E)
        assert res.status == tritools.UncertaintyStatus.BOUNDED, (radius, E, res.status)
        assert res.contains(X)
    many = tritools.uncertainty_many([CAMS] * 2, [regions] * 2, estimates=np.array([[-1.0, 0.0, -5.0], X + 0.05]))
    assert all(r.status == tritools.UncertaintyStatus.BOUNDED and r.contains(X) for r in many)


def test_a_far_estimate_leaves_the_bounds_as_they_are():
    rng = np.random.default_rng(3)
    X = np.array([0.1, -0.2, 0.3])
    x = np.array([tritools.project(X, P) for P in CAMS]) + rng.uniform(-0.5, 0.5, (3, 2))
    regions = [tritools.Ellipse.circle(xi, 1.0) for xi in x]
    near = tritools.uncertainty(CAMS, regions, estimate=X)
    far = tritools.uncertainty(CAMS, regions, estimate=X + np.array([2e6, -3e6, -4e6]))
    assert near.bounded and far.bounded and near.contains(X)
    assert np.array_equal(near.lo, far.lo) and np.array_equal(near.hi, far.hi)
    assert np.array_equal(near.depth_lo, far.depth_lo) and np.array_equal(near.depth_hi, far.depth_hi)
    assert far.max_distance >= np.linalg.norm(X - far.estimate)


def test_truly_empty_sets_stay_empty():
    """Two rays that miss each other by far more than the discs: a Farkas certificate, and no point of S refutes it."""
    X = np.array([0.1, -0.2, 0.3])
    x = np.array([tritools.project(X, P) for P in CAMS])
    x[1] += [40.0, -40.0]
    regions = [tritools.Ellipse.circle(xi, 1.0) for xi in x]
    for E in (None, np.array([-1.0, 0.0, -5.0])):
        assert tritools.uncertainty(CAMS, regions, estimate=E).status == tritools.UncertaintyStatus.EMPTY


def test_an_affine_camera_is_refused_by_name():
    """Review 26b F3: a camera with third row (0, 0, 0, 1) passed validation and failed deep inside with 'SVD did not
    converge'."""
    cams = CAMS.copy()
    cams[1, 2] = [0.0, 0.0, 0.0, 1.0]
    regions = [tritools.Ellipse.circle([320.0, 240.0], 1.0)] * 3
    with pytest.raises(ValueError, match=r"cameras\[1\].*affine"):
        tritools.uncertainty(cams, regions)
    with pytest.raises(ValueError, match=r"point 1: cameras\[1\].*affine"):
        tritools.uncertainty_many([CAMS, cams], [regions, regions])


def _parallel_pair(r, d0=160.0, f=800.0, b=1.0):
    K = np.diag([f, f, 1.0])
    cams = np.array([K @ np.hstack([np.eye(3), [[-bx], [0.0], [0.0]]]) for bx in (0.0, b)])
    return cams, [tritools.Ellipse.circle([0.0, 0.0], r), tritools.Ellipse.circle([-d0, 0.0], r)]


@pytest.mark.parametrize("z_far", [1e10, 1e12])
def test_a_set_bounded_far_away_is_not_called_unbounded(z_far):
    """Review 26b F2: two parallel cameras whose discs leave a disparity f b / Z >= d0 - 2r = f b / z_far > 0, so S
    is bounded at depth z_far (exact); a near-recession direction of the solver was accepted as a ray."""
    r = (160.0 - 800.0 / z_far) / 2
    assert Fraction(160.0) - 2 * Fraction(r) > 0
    cams, regions = _parallel_pair(r)
    res = tritools.uncertainty(cams, regions)
    assert res.status != tritools.UncertaintyStatus.UNBOUNDED, res.hi
    assert res.status == tritools.UncertaintyStatus.FAILED or res.depth_hi.max() >= 800.0 / (160.0 - 2 * r) * 0.999


def test_a_true_ray_is_still_certified():
    """Discs wider than the disparity window (0 disparity inside): every depth from ~5 on is in S, a true ray."""
    cams, regions = _parallel_pair(81.0)
    res = tritools.uncertainty(cams, regions)
    assert res.status == tritools.UncertaintyStatus.UNBOUNDED
    assert res.hi[2] == np.inf and np.all(np.isfinite(res.lo[2:]))


def test_recedes_refuses_a_non_finite_direction_and_decides_exactly():
    """The exact recession test: a direction imaged at (-80, 0) in both parallel cameras (inside both discs of radius
    81 at (0, 0) and (-160, 0)) recedes, the optical axis (imaged at (0, 0), 160 from the second centre) does not,
    and a NaN direction is refused (not a Fraction error)."""
    from tritools.uncertain.sets import view_blocks
    from tritools.uncertain.witness import recedes

    cams, regions = _parallel_pair(81.0)
    blocks = view_blocks([regions])
    d = np.array([[-0.1, 0.0, 1.0], [0.0, 0.0, 1.0], [np.nan, 0.0, 1.0]])
    R = np.repeat(cams[None], 3, axis=0)
    got = [bool(recedes(blocks, R[[k]], d[[k]])[0]) for k in range(3)]
    assert got == [True, False, False]


@pytest.mark.parametrize("radius", [1e-9, 1e-3, 1.0])
def test_discs_centre_on_the_dlt_where_the_estimate_is_far(radius):
    """``uncertainty_discs`` (the SfM path): a stale estimate (a camera centre, 1e8 or 1e10 away) is only the
    reference of ``max_distance``; before, the solver was centred on it (boxes 2x / 8x wider at 1e8 / 1e10 for
    1e-3 px discs, and a local Farkas verdict taken far from the set)."""
    from tritools.uncertain import uncertainty_discs
    from tritools.uncertain.discs import solver_centres

    rng = np.random.default_rng(7)
    X = rng.normal(size=(4, 3)) * 0.3
    x = np.array([[tritools.project(Xm, P) for P in CAMS] for Xm in X])
    C = np.broadcast_to(CAMS, (4,) + CAMS.shape).copy()
    assert all(_in_discs_exact(CAMS, x[m], radius, X[m]) for m in range(4))
    base = uncertainty_discs(C, x, radius, X)
    assert np.array_equal(solver_centres(C, x, np.full((4, 3), radius), X), X)      # a good estimate is kept
    for E in (np.tile([-1.0, 0.0, -5.0], (4, 1)), X + 1e8, X - 1e10):
        res = uncertainty_discs(C, x, radius, E)
        for m, (b, r) in enumerate(zip(base, res)):
            assert r.status == tritools.UncertaintyStatus.BOUNDED, (E[m], r.status)
            assert r.contains(X[m])
            assert np.all(r.hi - r.lo <= (b.hi - b.lo) * (1 + 1e-3) + 1e-12), (r.hi - r.lo, b.hi - b.lo)
            assert r.max_distance >= np.linalg.norm(X[m] - E[m]) * (1 - 1e-12)


def test_discs_in_a_georeferenced_world_centre_on_the_dlt():
    """The DLT is solved in a world moved to the mean camera centre: at 1e6 m from the origin it still lands on
    the discs, and an estimate 1e4 off gives the box of the true point's."""
    from tritools.uncertain import uncertainty_discs

    T = np.array([3.0e6, -1.0e6, 2.0e5])
    shift = np.eye(4)
    shift[:3, 3] = -T                                      # P' = P [I, -T; 0, 1]: the world moved by T
    cams = np.array([P @ shift for P in CAMS])
    X = np.array([[0.1, -0.2, 0.3], [-0.2, 0.1, 0.0]]) + T
    x = np.array([[tritools.project(Xm, P) for P in cams] for Xm in X])
    C = np.broadcast_to(cams, (2,) + cams.shape).copy()
    base = uncertainty_discs(C, x, 0.5, X)
    res = uncertainty_discs(C, x, 0.5, X + 1e4)
    for m in range(2):
        assert res[m].status == base[m].status == tritools.UncertaintyStatus.BOUNDED
        assert res[m].contains(X[m])
        assert np.all(res[m].hi - res[m].lo <= (base[m].hi - base[m].lo) * (1 + 1e-3) + 1e-6)
