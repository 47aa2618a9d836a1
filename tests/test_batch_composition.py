"""A problem's numbers do not depend on the other problems of its batch (review 19 F4).

A tiny-baseline two-view problem in a georeferenced world (pixels x 1e-3) was certified in some batches and refused
in others, depending on its neighbours: the enumeration's polish ran every row of a stack until all rows settled, a
singular row turned a whole stack's solves and inverses into pseudo-inverses, a stack of one took the scalar twins
(equal to the stacked code only up to round-off), and einsum's summation order for the epipoles varied with the
stack's shape.  Each row now gets the numbers it gets alone, in any stack of a batch."""
import numpy as np

import tritools
from tritools.model.stacked import damped_step, fundamental_stack
from tritools.solve.robust_enum import enum_candidates, subset_masks
from tritools.solve.robust_verify import polish_rows

#: the reviewer's case 4:492 (tiny baseline, world +1e6, pixels x 1e-3, c = [5e-4, 0.1]) and two neighbours: 472
#: (cameras whose normalisation is undefined) and 473 (an ordinary wrong match)
P492 = np.array([[[-5.0732034936770543e-01, -6.4316984195448434e-01, 2.6713033807052483e-01, -9.1258450357652572e+05],
                  [6.1507280121961794e-01, -5.4896769627324493e-01, 1.3386529665413213e-01, -1.7799408420931739e+06],
                  [5.7278456372604161e-02, -1.3168675267055840e-01, 9.8963517399426282e-01, -8.1546954871085240e+05]],
                 [[-4.3455573082783877e-01, 5.9536263055062810e-01, 4.4621144645618321e-01, 1.4021752687282150e+06],
                  [-6.4772983898262881e-01, -4.8992306186242396e-01, 1.9499089503585842e-01, -4.2961173220175836e+05],
                  [5.0233218833881321e-02, -1.6419443817371046e-01, 9.8514811586806927e-01, -8.7119615165702906e+05]]])
X492 = np.array([[0.31519225413203966, 0.23377914452937557], [0.3453320922480304, 0.2177286200678147]])
C492 = np.array([0.0005, 0.1])
P472 = np.array([[[-7.1644898483639008e-01, 2.0535215108869831e-01, 4.3235557839601246e-01, 9.1097549781578057e+05],
                  [-1.8632957697518596e-01, -7.7843101988776742e-01, 2.3859261518483454e-01, -1.4898287703927662e+06],
                  [1.3946465873170982e-01, -3.8414939389296736e-02, 9.8948163267266587e-01, -7.1103535384663625e+05]],
                 [[-4.6608176443589061e-01, -6.4280834717338187e-01, 3.3461204052537002e-01, -9.8684095017495030e+05],
                  [6.3144702319635626e-01, -5.4261351274446246e-01, 6.6672578198052945e-02, -1.7500103377838363e+06],
                  [1.7638555733803182e-01, -1.1695158044088926e-01, 9.7734869058843588e-01, -8.9896306351284578e+05]]])
X472 = np.array([[0.3119864846159471, 0.26496394597478284], [0.3109530551647812, 0.1942569177139153]])
C472 = np.array([0.001, np.inf])
P473 = np.array([[[-1.2452019451996974, -0.12207146578330179, 0.7547424313762253, 2.1079999999999997],
                  [0.21193632976605067, -0.2385767357930313, 1.1224413561834437, 1.1619999999999997],
                  [-0.4635807045358209, 0.521852819603307, 0.7160744130704225, 1.9999999999999996]],
                 [[-0.03767029128559697, -0.82332610622266, 1.2065573077040235, 2.108],
                  [0.990591019866594, 0.1022793999967635, 0.6082588433415934, 1.162],
                  [-0.035740314312710596, 0.16571720113944102, 0.9855254634860221, 2.0]]])
X473 = np.array([[0.9257799657864323, 0.6254751651420548], [1.3874178084486943, 0.483925868639521]])
C473 = np.array([0.1, 0.0005])


#: review 20 F1: six noise-free views, pixels x 1e6, c = [1e10, 1e10, inf, 1e10, 1e10, 1e4]: its bounds differed by 1e-3
#: relative between a batch where it was the only six-view problem (a stack of one, the single problem's order)
#: and a batch with another six-view problem (the staged order)
P6 = np.array([
    [[-7.2108241890234768e+08, 1.0571532349618010e+08, 4.5963508953085500e+08, 1.4658746546118605e+09],
     [-5.1904843159631640e+08, 2.8439790210815962e+07, -6.5374299536604500e+08, 1.1928036764042740e+09],
     [-5.4687571923767198e-01, -8.3665124949657921e-01, 3.0686062375152232e-02, 4.0336760480197666e+00]],
    [[-6.3372996820986176e+08, 4.9221312644157952e+08, 3.1386711447893584e+08, 3.1368411701665111e+09],
     [3.7746960363373584e+08, 1.8118943326489082e+08, 7.2269432515119302e+08, 1.9589898867759926e+09],
     [2.3331167962033991e-01, 9.7182751430552561e-01, -3.3420691068251594e-02, 9.6938972870779025e+00]],
    [[6.3217835325261962e+08, -5.3094144284015429e+08, 2.4668140171812946e+08, 3.4722942513046632e+09],
     [5.7730696663444686e+08, 5.9358224275535071e+08, 1.0943850949670860e+08, 3.2993966734587073e+09],
     [1.7039950652595773e-01, 5.7230889484264025e-02, 9.8371166175081493e-01, 1.0985558685069842e+01]],
    [[4.0790518610816248e+07, -8.2663672254445791e+07, -8.5668130064853764e+08, 3.0485243742397394e+09],
     [-2.3221339290188700e+08, -8.0195575050860548e+08, -2.3321972111575872e+07, 1.8395640641376324e+09],
     [-9.0971357986289925e-01, -2.3796960558539183e-02, -4.1455386535552136e-01, 9.5813294775880120e+00]],
    [[-4.7348646199618638e+08, -1.9495419330804032e+08, -6.9296712246537721e+08, 2.6357309405273695e+09],
     [-7.1415599160069418e+08, -1.2903501916006042e+08, 4.1343824628497052e+08, 1.9088345657977080e+09],
     [-6.1616456441841938e-01, 7.4661286065166554e-01, -2.5081958827929707e-01, 8.3632804620199543e+00]],
    [[-4.2104289273341650e+08, -6.4151397596591949e+08, -3.9189628872837561e+08, 2.3308625280606380e+09],
     [1.1904919884347288e+07, -5.2452942681439322e+08, 6.4986702738968933e+08, 1.8088747037541494e+09],
     [-9.4292057648718208e-01, -7.7768919450764654e-02, 3.2380979232342705e-01, 8.2973958999027548e+00]]])
X6 = np.array([[3.3740226592968351e+08, 2.7261217669252211e+08], [3.2559122027614713e+08, 2.0013362643324000e+08],
               [3.3328089726159370e+08, 2.6754753352376515e+08], [3.1530825900740623e+08, 2.3324216794671661e+08],
               [3.4394874114314586e+08, 2.5768871345782292e+08], [3.1775045991705745e+08, 2.4572184181359452e+08]])
C6 = np.array([1e10, 1e10, np.inf, 1e10, 1e10, 1e4])


def test_a_batch_takes_the_staged_order_for_a_view_count_of_one_problem():
    """The only six-view problem of a batch gets the numbers it gets beside other six-view problems (enumerate_many
    staged=True in batches; robust_batch's frames by the stacked normalisation), and those of a batch of one."""
    from tritools.scene import robust_protocol_scene

    rng = np.random.default_rng(4)
    six = [robust_protocol_scene(6, 1, 1.0, rng)[:2] for _ in range(2)]
    seen = set()
    for company in ([], [(P473, X473, C473)], [(p, x, np.full(6, 20.0)) for p, x in six]):
        probs = [(p, x) for p, x, _ in company] + [(P6, X6)]
        cs = [c for _, _, c in company] + [C6]
        seen.add(_key(tritools.triangulate_many(probs, robust=cs, progress=False)[-1]))
    assert len(seen) == 1, seen


def _key(r):
    return r.status, r.gamma_lb, r.gamma_ub, tuple(r.X), tuple(r.inliers)


def test_a_robust_problem_gets_the_same_result_in_any_batch():
    neighbours = {472: (P472, X472, C472), 473: (P473, X473, C473)}
    seen = set()
    for company in ([], [472], [473], [472, 473], [473, 472, 473]):
        probs = [neighbours[k][:2] for k in company] + [(P492, X492)]
        cs = [neighbours[k][2] for k in company] + [C492]
        seen.add(_key(tritools.triangulate_many(probs, robust=cs, progress=False)[-1]))
    assert len(seen) == 1, seen
    status, lb, ub, X, _ = seen.pop()
    assert 0.0 <= lb <= ub and np.isfinite(X).all()


def test_polish_rows_are_independent_of_their_stack():
    """enum_candidates: a row's candidate equals the row's candidate alone, bit for bit, beside rows that settle
    later (they used to keep every row stepping until all settled)."""
    rng = np.random.default_rng(3)
    Cn = rng.normal(size=(6, 4, 3, 4))
    Cn[:, :, 2, :3] += np.array([0.0, 0.0, 3.0])
    W = subset_masks(4)
    W = W[W.sum(axis=1) >= 2]
    rows = np.repeat(np.arange(6), 2)[:len(W)]
    stack = enum_candidates(Cn[rows], W[:len(rows)], by_size=True)
    for r in range(len(rows)):
        alone = enum_candidates(Cn[rows[r]][None], W[r][None], by_size=True)
        assert stack[r].tobytes() == alone[0].tobytes(), r
    X0 = rng.normal(size=(len(rows), 3))
    Cm = np.where(W[:len(rows), :, None, None], Cn[rows], 0.0)
    both = polish_rows(Cm, X0, 8)
    assert all(both[r].tobytes() == polish_rows(Cm[r:r + 1], X0[r:r + 1], 8)[0].tobytes() for r in range(len(rows)))


def test_a_singular_row_does_not_change_the_others():
    """damped_step and fundamental_stack with an exactly singular row in the stack: the other rows' numbers are their
    numbers alone (the whole stack used to fall back to pseudo-inverses)."""
    rng = np.random.default_rng(5)
    A = rng.normal(size=(3, 4, 3))
    JtJ = np.einsum("mki,mkj->mij", A, A)
    g = rng.normal(size=(3, 3))
    JtJ[1] = 0.0
    step = damped_step(JtJ, g, np.zeros(3))
    for r in (0, 2):
        assert step[r].tobytes() == damped_step(JtJ[r:r + 1], g[r:r + 1], np.zeros(1))[0].tobytes()
    assert np.isfinite(step).all()
    C = rng.normal(size=(3, 3, 3, 4))
    C[1, 0] = 0.0                                  # a camera of rank 0: C C^T singular
    F, defined = fundamental_stack(C)
    for r in (0, 2):
        Fr, dr = fundamental_stack(C[r:r + 1])
        assert Fr[0].tobytes() == F[r].tobytes() and np.array_equal(dr[0], defined[r])
    assert not defined[1, :2].any()
