import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import pytest  # noqa: E402


@pytest.fixture(scope="session")
def oxford_data():
    """The Oxford data directory (tritools.io.oxford.data_dir); skips the test when it is not found."""
    from tritools.io.oxford import DataNotFoundError, data_dir

    try:
        return data_dir()
    except DataNotFoundError:
        pytest.skip("Oxford data not found (../shared/data/oxford or $TRITOOLS_DATA)")


@pytest.fixture(scope="session")
def corridor_point(oxford_data):
    """(cameras (3, 3, 4), points2d (3, 2)) of the paper's corridor point (track 513, §5.1),
    the one Example 1 track Corollary 1 does not certify at delta = 2; skips without the data."""
    from tritools.io.oxford import load_sequence

    seq = load_sequence("corridor", oxford_data)
    track = seq.tracks[[t.track_id for t in seq.tracks].index(513)]
    return seq.problem(track)
