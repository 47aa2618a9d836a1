"""Wave 38: scalar twins on the single call's path give the stacked functions' numbers."""
import numpy as np
import pytest

from sospoly.analysis.verify import objective_scale_one, objective_scales


def _programs(rng):
    for n in (1, 2, 4, 6, 12):
        for _ in range(40):
            F2 = rng.standard_normal((n, n)) * 10.0 ** rng.integers(-30, 30)
            F2 = F2 + F2.T if rng.random() < 0.7 else F2
            f1 = rng.standard_normal(n) * 10.0 ** rng.integers(-30, 30)
            yield float(rng.standard_normal() * 10.0 ** rng.integers(-30, 30)), f1, F2
        yield 0.0, np.zeros(n), np.eye(n)
        yield 0.0, np.zeros(n), np.zeros((n, n))


def test_objective_scale_one_equals_stack():
    rng = np.random.default_rng(38)
    for f0, f1, F2 in _programs(rng):
        assert objective_scale_one(f0, f1, F2) == float(objective_scales(f0, f1, F2)[0])


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_objective_scale_one_non_finite_as_stack(bad):
    rng = np.random.default_rng(1)
    F2, f1 = rng.standard_normal((4, 4)), rng.standard_normal(4)
    for where in ("f0", "f1", "diag", "off"):
        f0, g, G = 0.5, f1.copy(), F2.copy()
        if where == "f0":
            f0 = bad
        elif where == "f1":
            g[2] = bad
        elif where == "diag":
            G[1, 1] = bad
        else:
            G[0, 3] = bad
        with np.errstate(invalid="ignore"):
            want = float(objective_scales(f0, g, G)[0])
        got = objective_scale_one(f0, g, G)
        assert got == want or (np.isnan(got) and np.isnan(want))
