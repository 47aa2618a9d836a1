"""camera_problems takes each distinct camera's rank once in a stack that repeats its cameras (review 33a M1: 40,000
tracks of 20 views hold 20 cameras; the rank rule ran on 800,000): the same verdicts as camera by camera."""
import numpy as np

from tritools.model import cameras as cm


def test_shared_cameras_give_the_verdicts_of_each_camera():
    rng = np.random.default_rng(3)
    pool = rng.standard_normal((12, 3, 4))
    pool[3, 2] = 2.0 * pool[3, 0] - pool[3, 1]                 # rank 2 exactly (in floats: up to rounding)
    pool[5] = 0.0
    pool[5, 0, 0] = pool[5, 1, 1] = 1.0                        # rank 2: a zero third row
    pool[7, 1, 2] = np.nan                                    # not finite
    pick = rng.integers(0, 12, size=(800, 7))
    C = pool[pick]
    assert C.shape[0] * C.shape[1] >= cm.SHARED_MIN_CAMERAS
    got = cm.camera_problems(C)
    ratio = cm.camera_rank_ratio(C)                            # camera by camera
    np.testing.assert_array_equal(cm.shared_rank_ratio(C), ratio)
    bad = ~np.isfinite(C).all(axis=(2, 3)) | ~(ratio > cm.CAMERA_RANK_RTOL)
    assert np.array_equal(got.valid, ~bad.any(axis=1) & ~cm.cameras_all_equal(np.nan_to_num(C)))
    assert got.valid.any() and not got.valid.all()


def test_distinct_cameras_take_the_direct_rule():
    C = np.random.default_rng(4).standard_normal((700, 7, 3, 4))       # no repeats: one camera each
    np.testing.assert_array_equal(cm.shared_rank_ratio(C), cm.camera_rank_ratio(C))
