"""A Lagrangian bound charges the error of its computed epipolar constraints times its multipliers (review 27b F1).

Six rectified cameras on a line (K [I | -0.5 k e_1]), keypoints of nearly zero disparity with one wrong match,
c = 10 px: the enumeration's candidate of the five right views sits near infinity, where the least-squares KKT
multipliers reach 5e13; a rounding of 1e-16 in the fundamental matrices then lifted that set's bound 0.16 px^2
above the value a finite point attains, and the TLS result was "certified" at gamma_LB 3.20784 while 3.20571 is
attained (exact rational arithmetic below)."""
from fractions import Fraction

import numpy as np
import pytest

import tritools

K = np.array([[800.0, 0, 320.0], [0, 800.0, 240.0], [0, 0, 1]])
CAMS = np.array([K @ np.hstack([np.eye(3), np.array([[-b], [0.0], [0.0]])]) for b in np.arange(6) * 0.5])
X_OBS = np.array([float.fromhex(h) for h in [
    '0x1.b6245ea34401bp+7', '0x1.590aa1a10f91ap+8', '0x1.e067ddbfb04f4p+7', '0x1.252d0fee46a91p+8',
    '0x1.c129a6aa427a7p+7', '0x1.58e5b824e618ep+8', '0x1.b622a0da634cep+7', '0x1.5779bf4f983ecp+8',
    '0x1.b7b3ecb961818p+7', '0x1.582b2465ac30ep+8', '0x1.b7e22c8aca282p+7', '0x1.57a918eb2c99dp+8']]).reshape(6, 2)
C_TLS = np.full(6, 10.0)
#: a finite point (3.8e3 in front of the rig) whose exact f_TLS is below the old certified bound
X_REF = np.array([-471.5114533437186, 495.4945811725208, 3802.4038714402486])


def _f_tls(X) -> Fraction:
    total = Fraction(0)
    Xh = [Fraction(float(v)) for v in X] + [Fraction(1)]
    for P, xi, ci in zip(CAMS, X_OBS, C_TLS):
        h = [sum(Fraction(float(P[r, k])) * Xh[k] for k in range(4)) for r in range(3)]
        d2 = (h[0] / h[2] - Fraction(float(xi[0]))) ** 2 + (h[1] / h[2] - Fraction(float(xi[1]))) ** 2
        total += min(d2, Fraction(float(ci)) ** 2)
    return total


@pytest.mark.parametrize("how", ["single", "many", "points"])
def test_no_tls_bound_above_an_attained_value_on_a_collinear_rig(how):
    if how == "single":
        r = tritools.triangulate(CAMS, X_OBS, robust=C_TLS)
        lb, ub, optimal, X = r.gamma_lb, r.gamma_ub, r.optimal, r.X
    elif how == "many":
        r = tritools.triangulate_many([(CAMS, X_OBS)], robust=C_TLS)[0]
        lb, ub, optimal, X = r.gamma_lb, r.gamma_ub, r.optimal, r.X
    else:
        r = tritools.triangulate_points(CAMS, X_OBS[None], robust=C_TLS, layout="points_views")
        lb, ub, optimal, X = r.gamma_lb[0], r.gamma_ub[0], bool(r.optimal[0]), r.X[0]
    attained = _f_tls(X_REF)
    assert 12 * Fraction(float(lb)) ** 2 <= attained            # (was 3.20784 against 3.20571 attained)
    assert 12 * ub ** 2 >= float(_f_tls(X)) * (1 - 1e-12)
    if optimal:
        assert 12 * ub ** 2 <= float(attained) * (1 + 1e-9)


def test_the_constraint_margin_is_the_multipliers_times_the_data_error():
    from sospoly.analysis import verify_quadratic_batch
    from sospoly.analysis.verify import constraint_margin

    # min x^2 + y^2 s.t. g = x - 1 = 0 with g known to within e: the bound drops by |lambda| e = 2 e
    f1, F2 = np.zeros((1, 2)), np.eye(2)[None]
    g0, g1, G2 = np.array([[-1.0]]), np.array([[[1.0, 0.0]]]), np.zeros((1, 1, 2, 2))
    exact = verify_quadratic_batch(np.zeros(1), f1, F2, g0, g1, G2, np.array([[1.0, 0.0]]), radius=1.0)
    loose = verify_quadratic_batch(np.zeros(1), f1, F2, g0, g1, G2, np.array([[1.0, 0.0]]), radius=1.0,
                                   constraint_error=np.array([[1e-3]]))
    assert abs(float(exact.lower_bound[0]) - 1.0) < 1e-12
    assert float(exact.lower_bound[0]) - float(loose.lower_bound[0]) == pytest.approx(2e-3, rel=1e-9)
    assert constraint_margin(np.array([[2.0, -3.0]]), np.array([[1.0, 1.0]]))[0] >= 5.0
