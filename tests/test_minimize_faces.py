"""``minimize`` on objectives whose Gram matrices lie on a singular face (review 11 F2: Rosenbrock's bound was refused)
and the INACCURATE contract of docs/sospoly.md.  References are analytic minima (Rosenbrock: 0 at (1, 1)) or
scipy multi-start, never the code's own earlier output."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize as sp_minimize

import sospoly as sp
from sospoly import SolveStatus
from sospoly.analysis.exact_face import face_exact_check
from sospoly.solvers import RawStatus
from sospoly.testing import Canned, FakeBackend, suboptimal

x, y = sp.variables("x y")


def rosenbrock(a, b):
    return (1 - a) ** 2 + 100 * (b - a ** 2) ** 2


def test_rosenbrock_lower_bound_is_proven_and_optimal():
    """The minimum 0 is attained at (1, 1) and f is SOS: the bound is proven (exactly, on the face) and meets f."""
    res = sp.minimize(rosenbrock(x, y))
    assert res.optimal and res.status == SolveStatus.OPTIMAL
    assert -1e-6 * res.scale <= res.lower_bound <= 0.0
    assert np.allclose(res.minimizers[0], [1.0, 1.0], atol=1e-4)


@pytest.mark.parametrize("f_scale, v_scale", [(1e-6, 1.0), (1e6, 1.0), (1.0, 1e3), (1e3, 1024.0), (1e-3, 1e3)])
def test_rosenbrock_rescaled_bound_is_valid(f_scale, v_scale):
    """f_scale * R(v_scale x, v_scale y), minimum 0 at (1 / v_scale, 1 / v_scale): every reported bound is <= 0,
    and these exactly representable data (the face relation 100 - 200 + 100 = 0 survives) are certified."""
    res = sp.minimize(f_scale * rosenbrock(v_scale * x, v_scale * y))
    assert res.lower_bound is not None and res.lower_bound <= 0.0
    assert res.optimal, res.message
    assert np.allclose(np.asarray(res.minimizers[0]) * v_scale, [1.0, 1.0], atol=1e-4)


def _scipy_min(f, starts):
    vals = [sp_minimize(lambda v: float(f(v)), s0, method="BFGS", options={"gtol": 1e-12}).fun for s0 in starts]
    return min(vals)


@pytest.mark.parametrize("shift, tilt", [(3.7, 0.0), (-1e-4, 0.0), (0.0, 1e-3), (0.0, -2.0)])
def test_perturbed_rosenbrock_bounds_stay_below_the_minimum(shift, tilt):
    """R + shift + tilt x (off the face's exact data when tilted): the lower bound never exceeds the minimum found by
    scipy multi-start (the true minimum is <= that)."""
    f = rosenbrock(x, y) + shift + tilt * x
    ref = _scipy_min(f, np.random.default_rng(0).uniform(-2, 2, size=(12, 2)))
    res = sp.minimize(f)
    assert res.lower_bound is None or res.lower_bound <= ref + 1e-12
    if tilt == 0.0:
        assert res.optimal and abs(res.lower_bound - shift) <= 1e-6 * res.scale


def test_face_check_refuses_levels_above_the_minimum():
    """The exact face proof is a proof: at a level above min f = 0 it must fail (for every margin >= 0 tried), and
    at the solver's level it proves a bound <= 0 on the face of e_y + e_x2."""
    ps = sp.build_psatz(rosenbrock(x, y), degree=4, multiplier=1.0, sparsity="newton")
    lb = sp.solve_psatz(ps)
    ok = face_exact_check(ps, lb.solution, lb.lower_bound, [1e-10, 1e-9, 1e-8, 1e-7])
    assert ok.ok and ok.level <= 0.0 and ok.faces == 1
    for c in (1e-3, 1e-7, 1e-9):
        bad = face_exact_check(ps, lb.solution, c, [0.0, 1e-12])
        assert not bad.ok and bad.level == -np.inf


def test_inaccurate_status_carries_only_proven_bounds():
    """docs/sospoly.md: INACCURATE with a lower_bound only when it was proven from the iterate (the message says
    so), and that bound is valid; an iterate of a weaker certificate is never reported optimal."""
    (t,) = sp.variables("t")
    fake = FakeBackend([Canned(RawStatus.ALMOST_SOLVED, suboptimal(0.5))] * 12)
    res = sp.minimize((t - 1) ** 2 + 2, degree=2, backend=fake)
    assert res.status == SolveStatus.INACCURATE and not res.optimal
    assert res.lower_bound is not None and res.lower_bound <= 2.0 and "proven" in res.message
    fake = FakeBackend([Canned(RawStatus.ALMOST_SOLVED)] * 12)          # no iterate at all: nothing to prove
    res = sp.minimize((t - 1) ** 2 + 2, degree=2, backend=fake)
    assert res.lower_bound is None and not res.optimal
