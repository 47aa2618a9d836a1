"""Tests of sospoly.algebra.polynomial against sympy (an independent computer-algebra implementation).

Every reference value here comes from sympy's own ``expand`` / ``diff`` / ``subs`` / ``Matrix.det``
or from numpy; integer coefficients keep the float arithmetic exact, so most comparisons are exact.
"""
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from sospoly import Polynomial, det, variables

sympy = pytest.importorskip("sympy")   # optional dependency (the 'sympy' / 'test' extras)

GENS = ("x", "y", "z")
SX, SY, SZ = sympy.symbols("x y z")


def rand_poly(rng, gens=GENS, maxdeg=3, nterms=5):
    """A random polynomial with small integer coefficients (exact in float arithmetic)."""
    terms = {}
    for _ in range(nterms):
        e = tuple(int(k) for k in rng.integers(0, maxdeg + 1, size=len(gens)))
        if sum(e) <= maxdeg:
            terms[e] = float(rng.integers(-5, 6))
    return Polynomial(gens, terms)


def sym(p):
    return p.to_sympy()


def from_sym(expr, gens=GENS):
    return Polynomial.from_sympy(sympy.expand(expr), gens)


@pytest.mark.parametrize("seed", range(5))
def test_arithmetic_matches_sympy_expand(seed):
    rng = np.random.default_rng(seed)
    p, q = rand_poly(rng), rand_poly(rng)
    P, Q = sym(p), sym(q)
    # reference: sympy.expand of the same expressions; integer data -> exact equality
    assert p + q == from_sym(P + Q)
    assert p - q == from_sym(P - Q)
    assert p * q == from_sym(P * Q)
    assert 3 * p - q / 2 == from_sym(3 * P - Q / 2)
    assert p**3 == from_sym(P**3)
    assert (p + 2) * (q - 1.5) == from_sym((P + 2) * (Q - sympy.Rational(3, 2)))
    assert -p == from_sym(-P)
    assert 1 - p == from_sym(1 - P)


def test_power_edge_cases():
    x, y = variables("x y")
    p = x + 2 * y
    assert p**0 == 1
    assert p**1 == p
    assert (p**2).coefficient((1, 1)) == 4.0
    with pytest.raises(ValueError):
        p ** -1
    with pytest.raises(ValueError):
        p ** 1.5


@pytest.mark.parametrize("seed", range(3))
def test_evaluation_vectorised_scalar_and_sympy(seed):
    rng = np.random.default_rng(100 + seed)
    p = rand_poly(rng, maxdeg=4, nterms=8)
    pts = rng.uniform(-2, 2, size=(40, 3))
    vec = p.evaluate(pts)
    assert vec.shape == (40,)
    scal = np.array([p(pt) for pt in pts])
    np.testing.assert_allclose(vec, scal, rtol=1e-13, atol=1e-13)
    # independent reference: sympy evaluation of the same polynomial (rtol 1e-12, float rounding only)
    P = sym(p)
    for pt in pts[:5]:
        ref = float(P.subs({SX: pt[0], SY: pt[1], SZ: pt[2]}))
        assert math.isclose(p(pt), ref, rel_tol=1e-12, abs_tol=1e-12)
    assert isinstance(p(pts[0]), float)


def test_evaluate_zero_polynomial_and_shape_check():
    x, y = variables("x y")
    z = x - x
    assert z.is_zero
    np.testing.assert_array_equal(z.evaluate(np.ones((3, 2))), np.zeros(3))
    with pytest.raises(ValueError):
        (x + y).evaluate(np.ones(3))


@pytest.mark.parametrize("seed", range(3))
def test_substitution_matches_sympy(seed):
    rng = np.random.default_rng(200 + seed)
    x, y, z = variables("x y z")
    p = rand_poly(rng, maxdeg=3, nterms=6)
    # a number for one variable and a polynomial for another
    out = p.subs({"x": 1.5, "y": z * z - 2 * z + 1})
    ref = from_sym(sym(p).subs({SX: sympy.Rational(3, 2), SY: SZ**2 - 2 * SZ + 1}), ("z",))
    # the substituted variables no longer occur (they may remain as unused generators)
    assert all(out.degree_in(g) <= 0 for g in out.gens if g != "z")
    assert out.allclose(ref, atol=1e-12, rtol=1e-12)
    # substituting all variables gives a constant equal to the evaluation
    full = p.subs({"x": 0.5, "y": -1.0, "z": 2.0})
    assert math.isclose(full.coefficient(()), p([0.5, -1.0, 2.0]), rel_tol=1e-12, abs_tol=1e-12)
    # Polynomial keys are accepted too
    assert p.subs({x: 1.5, y: z * z - 2 * z + 1}).allclose(ref, atol=1e-12, rtol=1e-12)


@pytest.mark.parametrize("seed", range(3))
def test_diff_matches_sympy(seed):
    rng = np.random.default_rng(300 + seed)
    p = rand_poly(rng, maxdeg=4, nterms=7)
    P = sym(p)
    for name, s in zip(GENS, (SX, SY, SZ)):
        assert p.diff(name) == from_sym(sympy.diff(P, s))
    grad = p.gradient()
    assert len(grad) == 3 and grad[1] == p.diff("y")
    assert p.diff("w").is_zero  # a variable the polynomial does not depend on


def test_degree():
    x, y, z = variables("x y z")
    p = x**3 * y + 2 * z**2 - 1
    assert p.degree == 4
    assert p.degree_in("x") == 3 and p.degree_in("y") == 1 and p.degree_in("z") == 2
    assert (p - x**3 * y).degree == 2  # exact cancellation removes the term
    assert (x - x).degree == -1
    assert Polynomial.constant(3.0, ("x",)).degree == 0


@pytest.mark.parametrize("seed", range(3))
def test_sympy_round_trip(seed):
    rng = np.random.default_rng(400 + seed)
    p = rand_poly(rng, maxdeg=4, nterms=6)
    assert Polynomial.from_sympy(p.to_sympy(), GENS) == p
    expr = (SX - 2 * SY) ** 3 + SZ * SX - 7
    back = Polynomial.from_sympy(expr, GENS).to_sympy()
    assert sympy.expand(back - expr) == 0


def test_generators_union_and_equality():
    (x,) = variables("x")
    (y,) = variables("y")
    s = x + y
    assert s.gens == ("x", "y")
    assert s([2.0, 3.0]) == 5.0
    assert (y * x).gens == ("y", "x")
    assert x * y == y * x  # equality is independent of generator order
    v = variables("v", n=4)
    assert [g.gens for g in v][0] == ("v1", "v2", "v3", "v4")


def _affine(rng, gens):
    return Polynomial(gens, {(0,) * len(gens): float(rng.integers(-3, 4)),
                             **{tuple(int(j == k) for j in range(len(gens))): float(rng.integers(-3, 4))
                                for k in range(len(gens))}})


@pytest.mark.parametrize("seed", range(3))
def test_det_4x4_affine_matches_sympy(seed):
    rng = np.random.default_rng(500 + seed)
    gens = ("a", "b", "c")
    M = [[_affine(rng, gens) for _ in range(4)] for _ in range(4)]
    d = det(M)
    # reference: sympy's determinant of the same symbolic matrix, expanded (integer data: exact)
    SM = sympy.Matrix([[e.to_sympy() for e in row] for row in M])
    ref = Polynomial.from_sympy(sympy.expand(SM.det(method="berkowitz")), gens)
    assert d == ref
    assert d.degree <= 4


def test_det_numeric_and_errors():
    rng = np.random.default_rng(7)
    A = rng.integers(-4, 5, size=(4, 4)).astype(float)
    d = det(A.tolist())
    assert math.isclose(d.coefficient(()), np.linalg.det(A), rel_tol=1e-9, abs_tol=1e-9)
    with pytest.raises(ValueError):
        det([[1, 2, 3], [4, 5, 6]])
    with pytest.raises(ValueError):
        det([])


# ---------------------------------------------------------------- hypothesis property tests
_coef = st.integers(-5, 5).map(float)
_exp2 = st.tuples(st.integers(0, 3), st.integers(0, 3))
_poly2 = st.dictionaries(_exp2, _coef, max_size=5).map(lambda t: Polynomial(("x", "y"), t))
_point = st.tuples(st.floats(-2, 2), st.floats(-2, 2))


@settings(max_examples=40, deadline=None)
@given(_poly2, _poly2, _point)
def test_property_product_evaluates_to_product(p, q, v):
    pq = (p * q)(v)
    ref = p(v) * q(v)
    # float rounding only: tolerance relative to the size of the factors
    assert math.isclose(pq, ref, rel_tol=1e-9, abs_tol=1e-9 * (1 + abs(p(v)) * abs(q(v))))
    assert math.isclose((p + q)(v), p(v) + q(v), rel_tol=1e-12, abs_tol=1e-9)


_aff = st.tuples(_coef, _coef, _coef).map(lambda c: Polynomial(("x", "y"), {(0, 0): c[0], (1, 0): c[1], (0, 1): c[2]}))
_row = st.lists(_aff, min_size=3, max_size=3)


@settings(max_examples=25, deadline=None)
@given(_row, _row, _row, _row, st.integers(-3, 3), st.integers(-3, 3), st.integers(0, 2))
def test_property_det_is_multilinear_in_rows(r0, r0b, r1, r2, a, b, k):
    rows = [r0, r1, r2]
    rows_b = list(rows)
    rows_b[k] = r0b
    mixed = list(rows)
    mixed[k] = [a * u + b * w for u, w in zip(rows[k], r0b)]
    # determinant multilinearity: det(.., a r + b r', ..) = a det(.., r, ..) + b det(.., r', ..)
    lhs = det(mixed)
    rhs = a * det(rows) + b * det(rows_b)
    assert lhs.allclose(rhs, atol=1e-9, rtol=1e-12)
    # alternating: swapping two rows flips the sign
    assert det([rows[1], rows[0], rows[2]]).allclose(-det(rows), atol=1e-9, rtol=1e-12)
