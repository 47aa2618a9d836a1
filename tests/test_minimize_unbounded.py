"""Issue 24, defect 7: ``sospoly.minimize`` must not certify a finite lower bound for a quadratic that is
unbounded below.  ``x^2 - 1e-6 x y`` (indefinite: det Q = -2.5e-13) was reported ``optimal`` with a lower
bound of -1.7e-10 although f(5e-7 t, t) = -2.5e-13 t^2 -> -inf.  Reference: the closed form (eigenvalues of
Q, the minimiser -Q^-1 b / 2 of a definite quadratic) and direct evaluation along the reported direction."""
from __future__ import annotations

import numpy as np
import pytest

from sospoly import SolveStatus, minimize, variables
from sospoly.analysis.recession import recession_direction


def _cases():
    x, y = variables("x y")
    return {"tiny_indefinite": x ** 2 - 1e-6 * x * y,
            "scaled_indefinite": 1e6 * x ** 2 + 2e3 * x * y + 0.29 * y ** 2 + 3 * x,
            "psd_with_linear_escape": x ** 2 + 2 * x * y + y ** 2 + y,
            "saddle": x * y,
            "odd_degree": x ** 3 + y ** 2}


@pytest.mark.parametrize("name", list(_cases()))
def test_unbounded_quadratics_get_no_lower_bound(name):
    f = _cases()[name]
    res = minimize(f)
    assert res.status == SolveStatus.INFEASIBLE and not res.optimal and res.lower_bound is None
    assert "unbounded below" in res.message
    d = recession_direction(f)
    values = [f(t * d) for t in (1e4, 1e8, 1e12)]
    assert values[2] < values[1] < values[0] and values[2] < -1.0      # f really decreases without bound


def test_bounded_quadratics_are_still_certified():
    x, y = variables("x y")
    f = (x - 1) ** 2 + (y + 2) ** 2 + 0.5 * x * y + 3.0
    Q = np.array([[1.0, 0.25], [0.25, 1.0]])
    b = np.array([-2.0, 4.0])
    xstar = np.linalg.solve(2 * Q, -b)
    fstar = f(xstar)
    res = minimize(f)
    assert res.optimal and res.lower_bound == pytest.approx(fstar, abs=1e-6)
    assert recession_direction(f) is None
    assert recession_direction(x ** 2 + y ** 2, ineq=(1 - x,)) is None     # constrained: not judged
