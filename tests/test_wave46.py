"""Wave 46: gamma_LB lowered by the round-off magnitude at the estimate (review 45a HIGH-1)."""
from __future__ import annotations

from fractions import Fraction

import numpy as np

import tritools
from tritools.model.magnitude import world_origin_magnitudes

# review 45a HIGH-1 (seed 82): view 1 is view 0 perturbed by ~2e-9 relative, the optimum 6e-8 (of the scene's size)
# from their centres; the default path certified gamma_LB = gamma_UB = 243.78541588759705 while the float data attain
# 243.7854135448648 at W below
P_DUP = np.array([
    [[-818.8097956533751, 264.626908651839, -43.853366569161494, 3200.455400113269],
     [-81.5258440058528, -98.81155179112224, -825.3422405231443, 2420.921913118945],
     [-0.6304079025773385, -0.7640716128076082, -0.13704177052862968, 9.999965758701213]],
    [[-818.8097959419092, 264.62690942720394, -43.8533667027297, 3200.4553923864178],
     [-81.52584415815744, -98.81155170502235, -825.3422362213807, 2420.9219230488047],
     [-0.6304079014736289, -0.7640716158855663, -0.1370417701750316, 9.999965660723118]],
    [[830.0397479822798, 204.1787797650224, -108.3745480414103, 3330.9301308959666],
     [-5.346046701211774, -44.80131872378328, -834.0049529980491, 2461.8109054308343],
     [0.11148528982070362, 0.9342769117857814, -0.3386704626294072, 9.998347423373025]]])
X_DUP = np.array([[26.162224177243047, -555.4058250792281], [-394.381104581882, -0.7899374972184035],
                  [344.2629192196974, -360.3827636152166]])
W_DUP = np.array([6.302225277251992, 7.6375533349164435, 1.3963288778337464])


def _exact_cost(P, x, X) -> Fraction:
    """sum_i ||pi_i(X) - x_i||^2 in rational arithmetic on the float data."""
    Xh = [Fraction(float(v)) for v in X] + [Fraction(1)]
    total = Fraction(0)
    for Pi, xi in zip(P, x):
        h = [sum(Fraction(float(Pi[r][c])) * Xh[c] for c in range(4)) for r in range(3)]
        total += (h[0] / h[2] - Fraction(float(xi[0]))) ** 2 + (h[1] / h[2] - Fraction(float(xi[1]))) ** 2
    return total


def _below(gamma_lb, P, x, X) -> bool:
    """gamma_LB <= gamma(X) exactly (2N gamma_LB^2 <= the exact cost)."""
    return 2 * len(P) * Fraction(float(gamma_lb)) ** 2 <= _exact_cost(P, x, X)


def test_near_duplicate_cameras_lower_bound_is_below_an_attained_cost():
    r = tritools.triangulate(P_DUP, X_DUP)
    assert r.gamma_lb is not None and r.gamma_lb <= r.gamma_ub
    assert _below(r.gamma_lb, P_DUP, X_DUP, W_DUP)
    assert _below(r.gamma_lb, P_DUP, X_DUP, r.X)
    # the same with the Theorem 1 program forced (its bound reached the clip too)
    t = tritools.triangulate(P_DUP, X_DUP, method="theorem1", delta=4, path="sdp")
    assert t.gamma_lb is None or _below(t.gamma_lb, P_DUP, X_DUP, W_DUP)


def test_estimate_magnitude_grows_next_to_a_camera_centre():
    # one camera at the origin looking down z; X at distance eps from its centre along a skew direction: the
    # projection of X moves by ~u |P| |X - o| / depth under a relative perturbation of the camera
    P = np.array([[[[800.0, 0.0, 320.0, 0.0], [0.0, 800.0, 240.0, 0.0], [0.0, 0.0, 1.0, 0.0]]]])
    o = np.array([[0.3, -0.2, 5.0]])
    x = np.array([[[300.0, 200.0]]])
    Ks = []
    for eps in (1e-2, 1e-4, 1e-6):
        X = np.array([[eps * 0.1, -eps * 0.2, eps]])
        Ks.append(float(world_origin_magnitudes(P, x, X, o, entries=True)[0]))
    assert Ks[0] < Ks[1] < Ks[2]
    assert Ks[2] > 1e5 * Ks[0] / 10                 # ~ 1 / depth
    # at the frame's own origin it is the origin term: about |x^| + |x| pixels
    K0 = float(world_origin_magnitudes(P, x, o, o, entries=True)[0])
    h = P[0, 0] @ np.append(o[0], 1.0)
    xhat = np.abs(h[:2] / h[2]).max()
    assert xhat <= K0 <= 4 * (xhat + 300.0)


def test_estimate_magnitude_is_infinite_at_a_camera_centre():
    P = np.array([[[[800.0, 0.0, 320.0, 0.0], [0.0, 800.0, 240.0, 0.0], [0.0, 0.0, 1.0, 0.0]]]])
    K = world_origin_magnitudes(P, np.zeros((1, 1, 2)), np.zeros((1, 3)), np.array([[0.0, 0.0, 5.0]]))
    assert K[0] == np.finfo(float).max


def test_estimate_magnitude_scalar_twin_equals_the_stack():
    from tritools.model.magnitude import world_origin_magnitude_one
    rng = np.random.default_rng(46)
    M, N = 60, 5
    C = rng.normal(size=(M, N, 3, 4)) * 10.0 ** rng.integers(-3, 4, size=(M, 1, 1, 1))
    x = rng.normal(size=(M, N, 2)) * 10.0 ** rng.integers(0, 6, size=(M, 1, 1))
    X = rng.normal(size=(M, 3)) + 10.0 ** rng.integers(0, 7, size=(M, 1)) * (rng.random((M, 1)) < 0.3)
    o = X + rng.normal(size=(M, 3)) * 10.0 ** rng.integers(-9, 1, size=(M, 1))
    X[0] = np.linalg.svd(C[0, 0])[2][-1][:3] / np.linalg.svd(C[0, 0])[2][-1][3]     # a camera centre: the maximum
    for entries in (False, True):
        K = world_origin_magnitudes(C, x, X, o, entries=entries)
        one = np.array([world_origin_magnitude_one(C[m], x[m], X[m], o[m], entries=entries) for m in range(M)])
        assert np.array_equal(K, one)
        assert K[0] == np.finfo(float).max and np.all(K > 0)
    # the estimate's terms only add
    assert np.all(world_origin_magnitudes(C, x, X, o, entries=True) >= world_origin_magnitudes(C, x, X, o))


def test_monomial_sup_is_one_rule_for_sospoly_and_the_constraint_errors():
    from sospoly.analysis import monomial_sup
    from tritools.model import coef_error
    E = np.array([[2, 0, 1], [0, 0, 0], [0, 3, 0]])
    r = np.array([2.0, np.inf, 0.5])
    out = monomial_sup(E, r)
    assert np.array_equal(out, [2.0, 1.0, np.inf])         # an absent variable counts 1, even at radius inf
    assert coef_error.monomial_sup is monomial_sup


def test_equal_cameras_are_ill_posed_in_batches_and_a_value_error_alone():
    """Review 44b LOW-2: a track seen only by duplicated images was ``invalid_input`` with a raw exception text."""
    from tritools.io.colmap import Camera, Image, Model, Point3D
    from tritools.sfm import retriangulate

    P = np.array([[[800.0, 0, 320, 0], [0, 800.0, 240, 0], [0, 0, 1.0, 5.0]]] * 2)
    x = np.array([[330.0, 250.0], [330.4, 249.7]])
    try:
        tritools.triangulate(P, x)
        raise AssertionError("equal cameras were accepted")
    except ValueError as exc:           # the single call's contract: a ValueError, now an IllPosedError
        assert isinstance(exc, tritools.IllPosedError) and "equal" in str(exc)
    for kw in ({}, {"robust": 5.0}):
        r = tritools.triangulate_many([(P, x)], **kw)[0]
        assert r.status == tritools.Status.ILL_POSED and not r.message.startswith(("ValueError", "IllPosedError"))
    cam = Camera(1, "PINHOLE", 640, 480, (800.0, 800.0, 320.0, 240.0))
    q, t = (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 5.0)
    images = {1: Image(1, q, t, 1, "a.jpg", ((330.0, 250.0, 1),)),
              2: Image(2, q, t, 1, "a_copy.jpg", ((330.4, 249.7, 1),))}
    model = Model({1: cam}, images, {1: Point3D(1, (0.0, 0.0, 0.0), (1, 1, 1), 0.0, ((1, 0), (2, 0)))})
    rec = retriangulate(model)[1].records[0]
    assert rec.status == tritools.Status.ILL_POSED and "ValueError" not in rec.message


def test_segments_kept_as_given_claim_no_ray():
    """Review 45b M2: with widen_roundoff=False two segments seen by parallel cameras (disparity >= 1e-9 px, so S is
    bounded at depth <= 8e11) were reported ``unbounded``: a ray certificate only the float test had checked."""
    f, cx, cy = 800.0, 320.0, 240.0
    K = np.array([[f, 0, cx], [0, f, cy], [0, 0, 1.0]])
    cams = np.array([K @ np.hstack([np.eye(3), [[-b], [0], [0]]]) for b in (0.0, 1.0)])
    s1 = tritools.Segment.from_endpoints([cx - 1, cy], [cx + 1, cy])
    s2 = tritools.Segment.from_endpoints([cx - 3, cy], [cx - 1 - 1e-9, cy])
    r = tritools.uncertainty(cams, [s1, s2], options=tritools.UncertaintyOptions(widen_roundoff=False))
    assert r.status != tritools.UncertaintyStatus.UNBOUNDED
    assert r.status == tritools.UncertaintyStatus.FAILED and np.all(np.isinf(r.hi)) and r.rigorous


def test_witnesses_lie_in_the_certified_box_in_a_georeferenced_world():
    """Review 45b L1: a witness 1 ulp (3.5e-10) below ``lo`` in a world at 3e6 (a negative gap)."""
    cams = np.array([
        [[860.6783764261411, -7.652778155359896, 39.675777736128246, -2637014804.6612825],
         [85.01104632561827, 794.031614080456, 244.71803742962928, 1088313227.4429486],
         [0.32805392110966775, -0.023914931735499675, 0.9443562362184402, -1976342.8636511308]],
        [[825.4372173733857, -30.105338624815232, 245.2489933948096, -2781769619.6975427],
         [28.29262382405055, 773.8727702552161, 312.9224550821952, 1149946549.2266612],
         [0.08964748110369135, -0.0940791832025476, 0.9915202652592154, -1448616.0795913518]],
        [[755.9023448575596, 30.175844498078597, 412.4331017846056, -2619786831.0723357],
         [-19.65350239603398, 819.0669812033656, 162.30532999866244, 1534790400.8550186],
         [-0.11967590681054673, 0.09429951405649561, 0.9883244806124061, -440692.7326995643]],
        [[660.6181703075125, -7.253184905382572, 553.1103184431499, -2549469729.698904],
         [-80.35567691321113, 794.3545822193009, 245.24225348626132, 1584535150.9346533],
         [-0.31129006412501, -0.022666202829320536, 0.9500445985459564, -61501.81447301066]]])
    B = np.array([[0.3076980567135272, 0.39410900255477416], [-0.18745937971581703, 0.4635288350864066],
                  [-0.49515743642934423, 0.06941983253163252], [-0.3076980567135274, -0.394109002554774],
                  [0.18745937971581708, -0.4635288350864066], [0.4951574364293442, -0.06941983253163302]])
    c = np.array([-158.374031882151, -11.851560924252627, 146.52247095789835, 158.37403188215103, 11.85156092425261,
                  -146.52247095789826])
    regs = [tritools.Point([330.63355915883625, 148.42936645105087]),
            tritools.Segment([349.2381487149846, 181.41526860406717], [-0.9579863993253944, 1.7556372229784734]),
            tritools.Ellipse([339.59516145550873, 159.91154735232632], [[4.0, 4.025549386344824e-18],
                                                                        [4.025549386344824e-18, 4.0]]),
            tritools.Polytope(B, c)]
    est = np.array([3000000.077610726, -2000000.5737687452, 1000000.2273863992])
    r = tritools.uncertainty(cams, regs, estimate=est, dilation=0.5)
    assert r.status == tritools.UncertaintyStatus.BOUNDED
    for W in (r.witness_lo, r.witness_hi):
        fin = np.all(np.isfinite(W), axis=1)
        assert fin.all()
        assert np.all((W >= r.lo) & (W <= r.hi))
    assert r.gap >= 0


# review 46a HIGH-2: views 0 / 1 near-duplicates (1e-9), the optimum ~1e-8 from their centres; every path certified
# gamma_LB = gamma_UB = 0.14363159127 while the float point W_46 costs 0.1436301226 exactly: the per-point
# normalisation formed P H by a plain product whose last column lost 11 digits next to the centres
P_46 = np.array([
    [[6.769424357261904, 754.7602116261003, -415.5613045508396, 1600.0000000000005],
     [-829.3537009662134, 71.75279427272788, -67.99981770343287, 1199.9999999999998],
     [-0.2729806805560048, 0.7548144548445554, 0.5964366578278845, 5.000000000000001]],
    [[6.769424357821644, 754.7602107379066, -415.5613050313737, 1600.000001569926],
     [-829.3536997634576, 71.75279435235507, -67.99981766182879, 1199.9999988253785],
     [-0.27298068075623894, 0.7548144542890476, 0.5964366569497458, 4.999999996977067]],
    [[546.7237279109207, -199.63562696553691, -635.3257288865789, 1600.0000000000005],
     [-530.6311563396276, 154.79677619453238, -626.1537622672641, 1200.0000000000002],
     [0.33868636122765367, 0.8159057137266563, -0.4686036865268635, 5.000000000000001]]])
X_46 = np.array([[3767.161979046111, 625.8183176970743], [2547.769255376599, 1647.4171222630648],
                 [1321.3981320569014, 465.20191659412694]])
W_46 = np.array([1.364903403289264, -3.774072281982612, -2.982183282853562])


def test_per_point_normalisation_keeps_the_frame_origin_exact_next_to_camera_centres():
    runs = [tritools.triangulate(P_46, X_46),
            tritools.triangulate(P_46, X_46, method="corollary1", delta=2, path="sdp"),
            tritools.triangulate_many([(P_46, X_46), (P_46, X_46)])[0]]
    for r in runs:
        assert r.gamma_lb is not None and _below(r.gamma_lb, P_46, X_46, W_46)



def test_a_transfer_that_still_contradicts_gamma_ub_reports_no_bound(monkeypatch):
    """Review 46a's second cause: a bound of the normalised problem that, lowered, is still above gamma(X) was clipped
    to gamma_UB and certified.  With the per-point normalisation of before (a plain product P H), the guard alone
    keeps every path from reporting a bound above an attained cost."""
    from sospoly import Tolerances
    from tritools.model.cameras import power2_scale
    from tritools.model.normalize import Normalization
    from tritools.solve.decide import transfer_contradicts

    tol = Tolerances()
    assert transfer_contradicts(1.01, 1.0, tol, 3, 1.0) and not transfer_contradicts(1.0 + 1e-12, 1.0, tol, 3, 1.0)
    assert np.array_equal(transfer_contradicts(np.array([1.01, np.nan, 0.5]), np.array([1.0, 1.0, 1.0]), tol, 3, 1.0),
                          [True, False, False])

    def plain(self, cameras):
        H = self.world()
        C = np.asarray(cameras, float)
        C = C / power2_scale(C, (1, 2))
        out = np.array([self.transform(i) @ P @ H for i, P in enumerate(C)])
        out = out / power2_scale(out, (1, 2))
        return out / np.linalg.norm(out, axis=(1, 2))[:, None, None]

    monkeypatch.setattr(Normalization, "cameras", plain)
    for r in (tritools.triangulate(P_46, X_46), tritools.triangulate(P_46, X_46, method="corollary1", delta=2,
                                                                     path="sdp")):
        assert r.gamma_lb is None or _below(r.gamma_lb, P_46, X_46, W_46)


def test_equal_cameras_with_an_infinite_threshold_keep_their_row():
    """Review 46c HIGH: robust=inf settles a problem by its L2 row; an ill_posed row went on to be validated again and
    raised IllPosedError out of the whole batch (every row lost; the CLI exited 1)."""
    P = np.array([[[800.0, 0, 320, 0], [0, 800.0, 240, 0], [0, 0, 1.0, 5.0]]] * 2)
    x = np.array([[330.0, 250.0], [330.4, 249.7]])
    K = np.array([[800.0, 0, 320], [0, 800.0, 240], [0, 0, 1.0]])
    good = np.array([K @ np.hstack([np.eye(3), [[0.0], [0], [5]]]), K @ np.hstack([np.eye(3), [[-1.0], [0], [5]]])])
    xg = np.array([[336.0, 272.0], [176.0, 272.0]])
    for c in (np.inf, [np.inf, np.inf]):
        out = tritools.triangulate_many([(P, x), (good, xg)], robust=c)
        assert [r.status for r in out] == [tritools.Status.ILL_POSED, tritools.Status.OPTIMAL]
    pts = tritools.triangulate_points(P, x[None], robust=np.inf)
    assert pts[0].status == tritools.Status.ILL_POSED
