import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import os  # noqa: E402

# Under pytest-xdist (pyproject's addopts run one worker per core) each worker keeps BLAS to one thread: two
# workers with a multi-threaded BLAS each oversubscribe the cores.  Set before numpy is first imported.
if os.environ.get("PYTEST_XDIST_WORKER") and "numpy" not in sys.modules:
    for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_var, "1")

import pytest  # noqa: E402
from hypothesis import settings as _hypothesis_settings  # noqa: E402

# Property tests draw the same examples on every run (a red CI means a defect, not an unlucky draw); their
# found counter-examples are pinned with @example.  `HYPOTHESIS_PROFILE=explore pytest ...` draws new ones.
_hypothesis_settings.register_profile("ci", derandomize=True)
_hypothesis_settings.register_profile("explore", derandomize=False)
_hypothesis_settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


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


# ----------------------------------------------------------------------------------------------- test tiers
#: The slow tier (`pytest -m slow`; `pytest -m "not slow"` is the ~2-minute loop of a developer, CI runs every
#: tier): end-to-end runs of the command line in subprocesses, the docs' code blocks, the benchmark scripts, the
#: fuzzers, and single tests measured above ~3 s on the 2-core machine.  One place: a test marked here needs no
#: decorator of its own (``@pytest.mark.slow`` in a test file works as well).
SLOW_TESTS = (
    "tests/test_docs.py", "tests/test_benchmark_scripts.py", "tests/test_colmap_benchmark.py",
    "tests/test_cli_conventions.py", "tests/test_fuzz_inputs.py", "tests/test_startup_interrupt.py",
    "tests/test_packaging_sospoly.py", "tests/test_api_docs.py::test_generation_is_deterministic",
    "tests/test_camera_models.py::test_cli_full_opencv_and_fisheye_models_certify_and_equirectangular_exits_3",
    "tests/test_uncertainty_sfm.py::test_bounded_noise_coverage_many_points",
    "tests/test_manyview.py::test_default_certifies_mixed_regions_through_the_views_formulation",
    "tests/test_manyview.py::test_views_formulation_is_never_stronger_than_dense_and_both_are_sound",
    "tests/test_cheirality.py::test_cli_", "tests/test_compiled.py::test_batched_ipm_agrees_with_clarabel",
    "tests/test_cli.py::test_python_m_and_console_script_dispatch",
    "tests/test_safe_outputs.py::test_two_writers_to_one_out", "tests/test_safe_outputs.py::test_two_colmap_runs",
    "tests/test_fastpath.py::test_oxford_subset_fast_path_agrees_with_sdp",
    "tests/test_sparse_minimize.py::test_n200_default_call", "tests/test_sparse_minimize.py::test_n100_default_call",
    "tests/test_dataset_cli.py::test_dataset_house_reproduces_table_5",
    "tests/test_example5_gaps.py", "tests/test_robust.py::test_points_bounds_against_enumeration_8_views",
    "tests/test_robust.py::test_other_regions_bounds_against_enumeration",
    "tests/test_baselines.py::test_hartley_sturm_matches_dense_multistart_nelder_mead",
    "tests/test_regressions_14_15.py::test_regions_that_ran_for_minutes_return_within_the_time_limit",
    "tests/test_triangulate.py::test_random_regions_bounds_are_consistent_with_local_search",
    "tests/test_soundness.py::test_property_bounds_are_ordered_and_below_the_reference",
    "tests/test_tpml.py", "tests/test_time_limits_build.py", "tests/test_cheirality.py::test_oxford_",
    # measured 5-10 s each on the loaded 2-core machine; the same path stays in the fast tier through the test
    # named after each: a benchmark script (the benchmark-script tests are slow) ...
    "tests/test_sparse_minimize.py::test_benchmark_quick_run",
    # ... the other four problems of the same comparison ...
    "tests/test_sparse_minimize.py::test_dense_and_sparse_agree[chained_singular-6]",
    # ... seed 0 of the same region kind ...
    "tests/test_uncertainty.py::test_true_point_and_sampled_points_covered[ellipse-1]",
    "tests/test_uncertainty.py::test_true_point_and_sampled_points_covered[ellipse-2]",
    # ... test_atomic_helpers_leave_the_target_on_failure_and_name_it (the same atomic write, in process; these
    # two run the command line in subprocesses under a file-size limit) ...
    "tests/test_safe_outputs.py::test_solve_output_under_a_file_size_limit_keeps_the_old_file",
    "tests/test_safe_outputs.py::test_dataset_csv_under_a_file_size_limit_keeps_the_old_file",
    # ... test_reduced_ipm_equals_unreduced_ipm_and_clarabel (the reduced IPM against Clarabel on Example 4) ...
    "tests/test_theorem1_speed_paths.py::test_example5_cases_agree_with_clarabel",
    # ... the "putinar" and "fixed" cases, the two certificates "auto" tries in turn.
    "tests/test_rigor_adversarial.py::test_unbounded_cubic_is_never_bounded[auto]",
)


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.nodeid.startswith(SLOW_TESTS):
            item.add_marker(pytest.mark.slow)
