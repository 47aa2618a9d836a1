"""Camera centres that agree to round-off but not exactly (review 8b F1): exact centres, the excluded ball, and
rotation rigs built in floats, which must not be certified as one centre."""
from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

import tritools
from tritools.model.constraints import centre_relations
from tritools.model.exact import exact_centre, same_exact_centre
from tritools.model.micro_baseline import BALL_RATIO, admitted_pairs, ball_lower_cost, group_ball
from tritools.model.regions import as_regions

K = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])


def _cam(C, z, rng):
    z = z / np.linalg.norm(z)
    x = np.cross(rng.normal(size=3), z)
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z])
    return K @ np.hstack([R, (-R @ C)[:, None]])


def _project(P, X):
    h = P @ np.append(X, 1.0)
    return h[:2] / h[2]


def _exact_cost(Ps, xs, X) -> Fraction:
    tot = Fraction(0)
    Xh = [Fraction(float(v)) for v in X] + [Fraction(1)]
    for P, x in zip(Ps, xs):
        h = [sum(Fraction(float(P[r, k])) * Xh[k] for k in range(4)) for r in range(3)]
        tot += (h[0] / h[2] - Fraction(float(x[0]))) ** 2 + (h[1] / h[2] - Fraction(float(x[1]))) ** 2
    return tot


def test_exact_centre_is_the_null_vector_in_integers():
    rng = np.random.default_rng(0)
    P = _cam(rng.normal(size=3) * 10, rng.normal(size=3), rng)
    c = exact_centre(P)
    ints = [[Fraction(float(v)) for v in row] for row in P]
    assert all(sum(r[k] * c[k] for k in range(4)) == 0 for r in ints)
    assert same_exact_centre(P, P) and same_exact_centre(P, 2.0 * P) and same_exact_centre(P, -0.25 * P)
    Q = P.copy()
    Q[0, 3] = np.nextafter(Q[0, 3], np.inf)                 # one ulp: another centre
    assert not same_exact_centre(P, Q)
    assert not same_exact_centre(P, np.zeros((3, 4)))


def test_the_ball_bound_is_below_every_point_of_the_ball():
    """ball_lower_cost <= the cost in the outside views at random points of the ball (and its surface)."""
    rng = np.random.default_rng(4)
    C = np.array([1.0, -2.0, 3.0])
    others = [np.array([6.0, 1.0, -2.0]), np.array([-4.0, 3.0, 1.0])]
    cams = np.array([_cam(C, -C, rng)] + [_cam(c, -c, rng) for c in others])
    x = rng.uniform(0, 640, size=(3, 2))
    regs = as_regions(x)
    for rho in (1e-6, 1e-3, 0.1, 1.0):
        lb = ball_lower_cost(cams, regs, [1, 2], C, rho)
        d = rng.normal(size=(400, 3))
        d *= rho * rng.uniform(0, 1, size=(400, 1)) ** (1 / 3) / np.linalg.norm(d, axis=1, keepdims=True)
        d[:50] *= rho / np.linalg.norm(d[:50], axis=1, keepdims=True)
        costs = [sum(np.sum((_project(cams[k], C + e) - x[k]) ** 2) for k in (1, 2)) for e in d]
        assert lb <= min(costs)
        assert lb > 0 if rho <= 1e-3 else True
    assert ball_lower_cost(cams, regs, [1, 2], C, 1e6) == 0.0       # the ball reaches the cameras


def test_a_rescaled_duplicate_is_admitted_only_when_its_ball_is_excluded():
    rng = np.random.default_rng(2)
    C1, C2 = np.array([1.0, -2.0, 3.0]), np.array([6.0, 1.0, -2.0])
    X = np.array([0.1, 0.2, -0.3])
    P1, P2 = _cam(C1, X - C1, rng), _cam(C2, X - C2, rng)
    cams = np.array([P1, 3.0 * P1, P2])
    assert not same_exact_centre(cams[0], cams[1])          # 3 P rounds: a micro-baseline
    x = np.array([_project(P, X) for P in cams]) + rng.normal(size=(3, 2))
    regs = as_regions(x)
    groups = np.array([0, 0, 2])
    untied = centre_relations(cams, groups).untied
    assert untied == ((0, 1),)
    assert group_ball(cams, [0, 1]) < BALL_RATIO * 1e-14
    assert admitted_pairs(cams, cams, regs, groups, 10.0, pairs=untied) == {(0, 1)}
    assert admitted_pairs(cams, cams, regs, groups, 1e12, pairs=untied) == frozenset()      # not excluded
    assert admitted_pairs(cams, cams, regs, groups, None, pairs=untied) == frozenset()
    res = tritools.triangulate(cams, x)
    assert res.optimal, res.message


@pytest.mark.parametrize("sep", [0.0, 1e-12])
def test_rotation_rig_built_in_floats_gets_no_one_centre_certificate(sep):
    """Review 8b F1 (its reproducer): four views whose centres agree to round-off; a float point 3e-9 from the
    centres has an exact cost below the one-centre bound that was certified.  Now: ill_posed (L2) / a valid
    bound (robust), never a bound above that exact cost; the same rig with one exact centre is certified."""
    rng = np.random.default_rng(8)
    rng.integers(2, 6)
    C0 = rng.normal(size=3) * 10
    X = rng.normal(size=3)
    rng.choice([0.0])
    Ps = np.array([_cam(C0 + rng.normal(size=3) * sep, X - C0 + rng.normal(size=3) * 0.05, rng) for _ in range(4)])
    xs = np.array([_project(P, X) for P in Ps]) + rng.normal(size=(4, 2))
    Xr = np.array([-13.366427933612174, -13.611067087837554, -3.5161713131989942])
    f_ref = _exact_cost(Ps, xs, Xr) if sep else None
    for kw in ({}, {"robust": 3.0}):
        res = tritools.triangulate(Ps, xs, **kw)
        assert not res.optimal, (kw, res.status, res.gamma_lb)
        if res.gamma_lb is not None and f_ref is not None:
            assert Fraction(8) * Fraction(res.gamma_lb) ** 2 <= f_ref
    res = tritools.triangulate(Ps, xs)
    assert res.status == tritools.Status.ILL_POSED and "round-off" in res.message
    # the rig with one exact centre: the world origin at C0 (t = 0 in every camera)
    P0 = Ps.copy()
    P0[:, :, 3] = 0.0
    x0 = np.array([_project(P, X - C0) for P in P0]) + rng.normal(size=(4, 2))
    assert tritools.triangulate(P0, x0).optimal


def test_minors_touching_an_untied_pair_are_dropped():
    """Review 9 F2: Theorem 1's minors with rows of both views of a round-off pair imply the pair's homography to
    round-off.  With the pair untied, every remaining minor vanishes at image points consistent pairwise with view 2
    but not related by the pair's homography (x1 from another point on view 2's ray); with it tied, some do not."""
    import sospoly
    from tritools.model.constraints import centre_relations, theorem1_constraints

    rng = np.random.default_rng(5)
    C1, C2 = np.array([1.0, -2.0, 3.0]), np.array([6.0, 1.0, -2.0])
    X = np.array([0.1, 0.2, -0.3])
    P0, P2 = _cam(C1, X - C1, rng), _cam(C2, X - C2, rng)
    cams = np.array([P0, 3.0 * P0, P2])
    rel = centre_relations(cams)
    assert rel.coincident == frozenset() and rel.untied == ((0, 1),)
    X2 = C2 + 0.7 * (X - C2)                                # on view 2's ray: the same x2, another x1
    v = np.concatenate([_project(cams[0], X), _project(cams[1], X2), _project(cams[2], X)])
    gens = sospoly.variables(" ".join(f"x{k}" for k in range(6)))[0].gens

    def worst(untied):
        polys, _ = theorem1_constraints(cams, gens, np.arange(6), rel.groups, untied)
        return max(abs(p(v)) / np.sum(np.abs(p.coefficients()) * np.prod(np.abs(v) ** p.exponents(), axis=1))
                   for p in polys)

    assert rel.loose == {1}
    assert worst(rel.loose) <= 1e-12
    assert worst(()) > 1e-6


def test_georeferenced_point_next_to_a_camera_is_never_certified_without_an_upper_bound():
    """Review 9 F1: three cameras ~10 apart at |C| ~ 3e7, the point 1e-6 in front of camera 0: the bounds met in the
    re-centred frame, but in the caller's frame view 0's projection is undefined (gamma_UB = inf).  The world-frame
    stage now applies report_point's rule: no finite gamma_UB, no certificate; single and batch agree."""
    Ps = np.array([[[-786.834059157399, -209.33209902332564, -281.90820432967064, 4807105649.093748],
                    [-2.4502513556330485, 521.2226212002481, -652.6262141666062, -25897118880.729],
                    [0.038971986539985716, -0.5683882873060232, -0.8218369297606751, -11296929.95915724]],
                   [[373.0711992146758, -656.5802649902789, 414.8737590422161, 18328163752.999397],
                    [-603.734472058473, -100.95010860266053, 568.2550156588043, 22660605488.263573],
                    [-0.4459212090961804, -0.8710086011242234, -0.20615113884192826, 14905834.910279652]],
                   [[105.0073193843348, -780.9657219162183, 348.5197326803697, 21666669961.391346],
                    [491.9616215062423, 247.95999641834064, 627.7655638382574, 6442777376.792823],
                    [-0.5312615088246834, -0.10607534764610276, 0.840541034015044, 28940695.738261502]]])
    xs = np.array([[353.4113106651477, 548.2311759737928], [833.7594095232242, 2036.2842210055446],
                   [51.81567794092531, 601.3804016344617]])
    results = [tritools.triangulate(Ps, xs), tritools.triangulate_many([(Ps, xs)])[0],
               tritools.triangulate_points(Ps, xs[None])[0]]
    for r in results:
        assert not (r.optimal and not np.isfinite(r.gamma_ub)), (r.status, r.gamma_ub)
    assert results[0].status == results[1].status == results[2].status


def test_centres_too_close_to_resolve_are_named_not_the_image_data():
    """Review 8b: ordinary 300 px data with centres 1e-11 apart ended in numerical_failure "the image data (|x| up to
    329) are too large ...": the message now names the centres' separation (image data up to 1e12 px are ordinary)."""
    rng = np.random.default_rng(501)
    N = int(rng.integers(3, 6))
    C0 = rng.normal(size=3) * 10
    X = rng.normal(size=3)
    Ps = np.array([_cam(C0 + rng.normal(size=3) * 1e-11, X - C0 + rng.normal(size=3) * 0.05, rng) for _ in range(N)])
    xs = np.array([_project(P, X) for P in Ps]) + rng.normal(size=(N, 2))
    res = tritools.triangulate(Ps, xs)
    assert not res.optimal and res.gamma_lb is None
    assert "too large" not in res.message and ("too close" in res.message or "round-off" in res.message), res.message
