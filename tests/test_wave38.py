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


def test_epipolar_errors_as_with_linalg_norm():
    """epipolar_errors with the stacked ``norms`` gives the numbers of its numpy.linalg.norm formula bit for bit."""
    from tritools.model.epipolar_data import EPIPOLAR_DATA_RTOL, epipolar_errors
    from tritools.model.stacked import view_pairs

    rng = np.random.default_rng(5)
    for N in (2, 3, 6, 11):
        I, J = view_pairs(N)
        M = 7
        F = rng.standard_normal((M, len(I), 3, 3)) * 10.0 ** rng.integers(-5, 5, (M, len(I), 1, 1))
        F[0, 0] = 0.0
        v = rng.standard_normal((M, 2 * N)) * 10.0 ** rng.integers(-3, 6)
        R = rng.uniform(0.5, 100.0, M)
        vt = np.concatenate([v.reshape(M, N, 2), np.ones((M, N, 1))], axis=2)
        vi, vj = vt[:, I], vt[:, J]
        g = np.einsum("mka,mkab,mkb->mk", vi, F, vj)
        seen = 4 * np.abs(g) / (np.linalg.norm(vi, axis=2) * np.linalg.norm(vj, axis=2))
        base = EPIPOLAR_DATA_RTOL * np.linalg.norm(F, axis=(2, 3))
        e = np.maximum(base, np.where(np.isfinite(seen), seen, np.inf))
        want = np.where(base > 0, e * (1.0 + R[:, None] ** 2 / 2) * (1 + 1e-12), 0.0)
        assert np.array_equal(epipolar_errors(F, (I, J), v, R), want)
