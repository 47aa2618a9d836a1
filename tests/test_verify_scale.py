"""sospoly.analysis.verify_quadratic (and its stacked and banded twins) at any scale (review 21a F1): the tests of the
Lagrangian Hessian, of the stationarity residual and of the certificate are relative to the program's own scale, so
the maximiser of s (x + y) on a circle is never certified (its Lagrangian is negative definite at every scale) and
the minimiser always is, for the objective scaled by 1e-13..1e13 and the circle's radius 1e-6..1e13; the bound
never exceeds the closed-form minimum -s r sqrt(2) beyond round-off (rigorously so with ``radius``)."""
from __future__ import annotations

import math

import numpy as np
import pytest

import sospoly
from sospoly.analysis import SparseQuadratics, verify_quadratic, verify_quadratic_batch
from sospoly.analysis.verify_sparse import verify_quadratic_banded_batch

SCALES = [1e-13, 1e-11, 1e-6, 1.0, 1e6, 1e13]
RADII = [1e-6, 1.0, 1e6, 1e12, 1e13]


@pytest.mark.parametrize("s", SCALES)
@pytest.mark.parametrize("r", RADII)
@pytest.mark.parametrize("ball", [False, True])
def test_maximiser_refused_minimiser_certified_at_every_scale(s, r, ball):
    x, y = sospoly.variables("x y")
    f, g = s * (x + y), [x ** 2 + y ** 2 - r * r]
    u = np.array([1.0, 1.0]) / math.sqrt(2)
    radius = 1.5 * r if ball else None
    top = verify_quadratic(f, g, r * u, gens=("x", "y"), radius=radius)
    assert not top.certified and top.lower_bound is None            # an indefinite (negative definite) Lagrangian
    low = verify_quadratic(f, g, -r * u, gens=("x", "y"), radius=radius)
    f_min = -s * r * math.sqrt(2)
    assert low.certified
    assert low.lower_bound <= f_min + (0.0 if ball else 4e-16 * abs(f_min))
    assert low.lower_bound >= f_min - 1e-9 * abs(f_min)


def test_stacked_and_banded_twins_decide_alike_at_small_scale():
    """The stack of M > 1 programs (einsum code) and the banded verification refuse the small-scale maximiser and
    certify the minimiser, as the stack of one does."""
    s, u = 1e-13, np.array([1.0, 1.0]) / math.sqrt(2)
    pts = np.array([u, -u, u])
    M = len(pts)
    f0, f1, F2 = np.zeros(M), np.tile(s * np.ones(2), (M, 1)), np.zeros((M, 2, 2))
    g0, g1, G2 = -np.ones((M, 1)), np.zeros((M, 1, 2)), np.tile(np.eye(2), (M, 1, 1, 1))
    stacked = verify_quadratic_batch(f0, f1, F2, g0, g1, G2, pts, radius=np.full(M, 1.5))
    assert stacked.certified.tolist() == [False, True, False]
    banded = verify_quadratic_banded_batch(f0, f1, F2, g0, g1, SparseQuadratics.from_dense(G2), pts,
                                           radius=np.full(M, 1.5))
    assert not banded.certified[0] and not banded.certified[2]
    assert np.all(np.nan_to_num(banded.lower_bound, nan=-np.inf) <= -s * math.sqrt(2))
