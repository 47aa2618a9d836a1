"""The world-domain TPML-style baseline (issue 25): sum-of-ratios relaxation in the scene point's coordinates.
References: the certified optimum gamma* of Theorem 1 (paper Tables 8-10: 0.412, 0.138 and 0.760)."""
import numpy as np
import pytest

import sospoly as sp
import tritools
from tritools.result import Status
from tritools.scene import paper_example
from tritools.tpml import tpml_bound


@pytest.mark.slow
@pytest.mark.parametrize("k,gamma_star", [(2, 0.41153631), (3, 0.13778172), (4, 0.76011535)])
def test_tpml_degree4_on_the_paper_examples(k, gamma_star):
    cams, regions = paper_example(k)
    r = tpml_bound(cams, regions, 4, budget=sp.Budget(time_limit=60))
    assert r.result.status == Status.NO_CERTIFICATE and r.result.gamma_lb is None and r.result.optimal is None
    assert r.n_lmivar > 0 and r.result.n_lmivar == r.n_lmivar
    # the estimate's gamma is exact, so never below gamma*; here it reaches it
    assert r.result.gamma_ub >= gamma_star - 1e-7
    assert abs(r.result.gamma_ub - gamma_star) < 1e-5
    # the bound holds on the restricted set, which holds the optimum here: below gamma*
    assert r.gamma_bound is not None and r.gamma_bound <= gamma_star + 1e-6
    ref = tritools.triangulate(cams, regions, "theorem1", delta=4)
    assert ref.optimal and np.allclose(r.result.X, ref.X, atol=1e-4)


def test_tpml_refuses_over_budget_and_bad_degree():
    cams, regions = paper_example(4)
    r = tpml_bound(cams, regions, 6, budget=sp.Budget(max_gram_side=10))
    assert r.result.status == Status.BUDGET_EXCEEDED and r.result.X is None
    with pytest.raises(ValueError, match="degree"):
        tpml_bound(cams, regions, 3)


def test_tpml_is_a_listed_baseline():
    from tritools import baselines

    cams, regions = paper_example(4)
    assert "tpml" in baselines.__all__
    r = baselines.tpml(cams, regions, 6, budget=sp.Budget(max_gram_side=10))
    assert r.method == "tpml" and r.status == Status.BUDGET_EXCEEDED
