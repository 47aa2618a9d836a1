"""DataSlots.ineq_polynomials: the inequalities of DataSlots.polynomials without building every equality (the
rigorous bound of a 30-view program read its few inequalities by rebuilding ~450 polynomials)."""
import sospoly
from sospoly import variables


def _coeffs(p):
    return {tuple(int(k) for k in e): float(c) for e, c in zip(p.exponents(), p.coefficients())}


def test_ineq_polynomials_equal_the_full_rebuild():
    x, y, z = variables(["x", "y", "z"])
    f = x ** 2 + 2 * y ** 2 - x * z + 3 * z
    eq = [x * y - 1, y * z + x - 2, x ** 2 - z]
    ineq = [1 - x ** 2 - y ** 2, 4 - z ** 2 + 0.5 * x]
    ps = sospoly.build_psatz(f, eq, ineq, 2, "putinar")
    slots, theta = ps.structure.slots, ps.theta
    full = slots.polynomials(theta)
    only = slots.ineq_polynomials(theta)
    assert len(only) == len(ineq) == len(full[2])
    for a, b, ref in zip(only, full[2], ineq):
        assert _coeffs(a) == _coeffs(b)
        assert _coeffs(a) == {e: c for e, c in _coeffs(ref.with_gens(a.gens)).items() if c != 0.0}
    # a program without inequalities has none
    ps0 = sospoly.build_psatz(f, eq, (), 2, "putinar")
    assert ps0.structure.slots.ineq_polynomials(ps0.theta) == ()
