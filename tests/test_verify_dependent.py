"""Verification with dependent equality constraints (sospoly.analysis.verify: the second multipliers).

Epipolar constraints of four or more views are dependent at every feasible point (six constraints of rank five for
four views), so the Jacobian's transpose has a singular value at round-off.  Where it lands just above the
minimum-norm least squares' cut-off (eps * max(p, q)), its direction gets a huge multiplier: the Lagrangian Hessian
breaks or the constraint data's error times |lambda| swamps the bound, and the candidate was not certified in one
normalised frame while a frame differing at round-off certified it (review 35a L2: an eight-view TLS problem
certified by ``triangulate`` and not by ``triangulate_many``).  Any multipliers give a valid bound, so a program not
certified by the first ones is tried again with the directions below sqrt(eps) * s_max dropped.

Reference: min (x - 2)^2 + y^2 on the unit circle, given twice (once rescaled, with a tiny linear term eps * y that
keeps the feasible set {(1, 0), (-1, 0)}): the minimum is 1 at (1, 0), in closed form.
"""
from __future__ import annotations

import numpy as np
import pytest

import sospoly
from sospoly.analysis.verify import RETRY_RCOND, quadratic_parts, verify_quadratic, verify_quadratic_batch


X, Y = sospoly.variables("x y")


def _program(eps: float):
    x, y = X, Y
    return (x - 2) ** 2 + y ** 2, [x ** 2 + y ** 2 - 1, 2 * (x ** 2 + y ** 2 - 1) + eps * y]


@pytest.mark.parametrize("eps", [1e-12, 1e-13, 3e-14])
def test_dependent_constraints_certified(eps):
    f, g = _program(eps)
    ver = verify_quadratic(f, g, [1.0, 1e-6], radius=3.0, constraint_error=[1e-12, 1e-12])
    assert ver.certified
    assert 1.0 - 1e-9 <= ver.lower_bound <= 1.0          # a valid bound of the closed-form minimum, and a tight one
    lam = ver.multipliers
    assert lam[0] + 2 * lam[1] == pytest.approx(1.0)     # a KKT multiplier of the dependent pair
    assert np.max(np.abs(lam)) < 1.0                     # not the minimum-norm solution's 1e7-size direction


def test_not_certified_at_the_maximiser_and_bounds_stay_valid():
    f, g = _program(1e-12)
    ver = verify_quadratic(f, g, [-1.0, 1e-6], radius=3.0, constraint_error=[1e-12, 1e-12])
    assert not ver.certified                             # f(-1, 0) = 9 is the maximum
    assert ver.lower_bound is None or ver.lower_bound <= 1.0


def test_stack_equals_the_scalar_twin():
    """verify_quadratic_batch on a stack (the stacked code, with the retry on some rows only) decides as the
    scalar twin of each program, with equal bounds up to round-off."""
    cases = [(1e-12, [1.0, 1e-6]), (1e-13, [1.0, 1e-6]), (1e-6, [1.0, 1e-9]), (1e-12, [-1.0, 1e-6])]
    parts, singles = [], []
    for eps, v in cases:
        f, g = _program(eps)
        gens = f.gens
        f0, f1, F2 = quadratic_parts(f, gens)
        gp = [quadratic_parts(gk, gens) for gk in g]
        parts.append((f0, f1, F2, [p[0] for p in gp], [p[1] for p in gp], [p[2] for p in gp], v))
        singles.append(verify_quadratic(f, g, v, gens=gens, radius=3.0, constraint_error=[1e-12, 1e-12]))
    stack = [np.array([p[k] for p in parts], float) for k in range(7)]
    batch = verify_quadratic_batch(*stack, radius=3.0, constraint_error=np.full((len(cases), 2), 1e-12))
    assert batch.certified.tolist() == [s.certified for s in singles] == [True, True, True, False]
    for m, s in enumerate(singles):
        if s.lower_bound is None:
            assert np.isnan(batch.lower_bound[m])
        else:
            assert batch.lower_bound[m] == pytest.approx(s.lower_bound, rel=1e-12, abs=1e-12)
            assert batch.lower_bound[m] <= 1.0


def test_retry_cut_off_is_sqrt_eps():
    assert RETRY_RCOND == pytest.approx(np.sqrt(np.finfo(float).eps))


# review 35a L2 (its seed 7038): eight views at pixel scale 1e-3, four wrong matches, tight thresholds
_CAMS_7038 = np.array([
    0.0031607996944001487, 0.00018452563085857732, -0.0029858755017776466, 0.0038194215334659927,
    -0.0008614907291723966, 0.004189282829250747, -0.0007240537737222199, 0.00029157128858211655,
    0.0011927135665933436, 0.0005766425964330541, 0.0010024353479592492, 0.00743018965396535,
    1.983894849437704, -0.02779280531921174, 0.22969665766692698, 2.2118235669731248,
    0.018475400356163293, 1.943245756005271, 0.40991018473014573, 0.8769714752768278,
    0.044855968650364945, -0.0868525166225367, 0.9952108231087369, 5.322253751227952,
    1.3119271657096978, 0.15832444043156027, -0.4918996259621894, 2.635506067629946,
    -0.24952713064735318, 1.3121255275146533, -0.39930886504319146, 1.1283634100527,
    0.46052933051722256, 0.4947638763486259, 0.7369677349747683, 6.460736705356525,
    -0.006316517197447798, -0.00026484601129622405, 0.0007575187187242604, -0.0099253574675439,
    0.00012924585285635, -0.006299969870050052, 0.00040177513267725703, -0.004734415627720929,
    -0.001160998649302418, -0.0008276437853007001, -0.003609093646355071, -0.027192609710505446,
    0.980368172489837, 0.08207474618734184, 0.4060950222501583, 3.1249654282406127,
    0.00274675428004566, 1.0426724768692721, -0.028244397840252188, 1.8658802506992858,
    -0.09355503534213301, 0.2564835818354433, 0.9620102014069258, 7.608515527510873,
    2.0066575428212636, 0.07401541899788326, 0.2626664947957661, 2.411262795625139,
    -0.005562250440192289, 2.000972467548886, -0.22896442819914548, 0.262416277679974,
    0.0236273483193682, 0.2312981843683852, 0.9725959584119624, 3.2618817087824614,
    1.6292592139154325, -0.01346552436660123, -0.5299348678973592, 2.825562932294395,
    0.14951072262272777, 1.6715908655701475, 0.27226529828729135, 1.107871547686732,
    0.4809109737088266, -0.04207976364562884, 0.8757590586787877, 6.5907469248272275,
    1.188805002569844, 0.09401466996111782, 1.6571127860421018, 2.08128166128153,
    0.25987222711205527, 1.9978880534165093, -0.2534336788167907, 2.0026418915824697,
    -0.68432507467939, 0.2937958436284932, 0.6673703577712075, 6.014175866006886,
]).reshape(8, 3, 4)
_OBS_7038 = np.array([
    -94.86418254947051, -37.56385313389425, 0.25352378588424435, 0.23450773193574992,
    5.352213656370424, 4.994062673872696, 264.76216909130653, 280.22869792733655,
    -0.6223974447855459, 4.856200648194813, -0.04198103948354984, -0.6620435783659816,
    -19.163902450506082, -1.3708023404896, -7.1356357703668705, 3.6587919288692534,
]).reshape(8, 2)


@pytest.mark.slow
def test_tls_batch_row_certified_as_the_single_call():
    """The single call certified this problem and a batch row did not: the inlier set's four-view L2 sub-problem,
    verified in the parent's normalised frame, got the minimum-norm multipliers' 40-size direction in the batch's
    frame (its stacked normalisation differs from the single call's scalar twin at round-off) and no bound."""
    import tritools

    c = 0.0003882327755073853
    single = tritools.triangulate(_CAMS_7038, _OBS_7038, robust=c)
    row = tritools.triangulate_many([(_CAMS_7038, _OBS_7038)], robust=c)[0]
    for r in (single, row):
        assert r.optimal, r.message
        assert r.inliers.tolist() == [True, False, True, True, True, False, False, False]
    assert max(single.gamma_lb, row.gamma_lb) <= min(single.gamma_ub, row.gamma_ub)
