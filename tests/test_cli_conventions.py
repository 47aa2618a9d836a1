"""Command-line conventions, run as a user runs them (a subprocess): `| head` ends quietly, -v / --quiet /
--log-level, the program named once in an error, --progress without tqdm says so, help texts that match the
code's thresholds."""
import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1"}


def run(*args, **kw):
    return subprocess.run([sys.executable, "-m", "tritools", *map(str, args)], capture_output=True, text=True,
                          cwd=ROOT, env=kw.pop("env", ENV), timeout=300, **kw)


def problem_file(tmp_path, n):
    rng = np.random.default_rng(0)
    cams = [[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 1]], [[1, 0, 0, 1], [0, 1, 0, 0], [0, 0, 1, 1]]]
    probs = [{"name": f"p{k}", "cameras": cams, "regions": rng.normal(scale=0.1, size=(2, 2)).tolist()}
             for k in range(n)]
    path = tmp_path / "many.json"
    path.write_text(json.dumps({"problems": probs}))
    return path


def test_pipe_to_head_ends_quietly(tmp_path):
    """`tritools solve many.json --json | head -1`: no 'internal error: BrokenPipeError', exit 0."""
    path = problem_file(tmp_path, 1500)                  # ~1 MB of JSON: far beyond a pipe buffer
    proc = subprocess.Popen([sys.executable, "-m", "tritools", "solve", str(path), "--json"], cwd=ROOT, env=ENV,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    first = proc.stdout.readline()
    proc.stdout.close()                                  # what `head -1` does
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=300) == 0
    assert first.strip() in (b"[", b"{") and "error" not in err.lower()     # (the progress bar may be there)


def test_error_names_the_program_once():
    r = run("--bogus", "solve", "x.json")
    assert r.returncode == 2 and r.stderr.count("tritools") == 2        # "tritools: error: ... 'tritools --help'"
    assert r.stderr.startswith("tritools: error: unrecognized arguments: --bogus")
    r = run("dataset", "house", "--delta", "3")
    assert r.returncode == 2 and r.stderr.startswith("tritools: error: --delta") and len(r.stderr.splitlines()) == 1
    r = run("colmap")
    assert r.returncode == 2 and r.stderr.startswith("tritools: error: colmap: the following arguments are required")


def test_log_levels_and_quiet(tmp_path):
    path = problem_file(tmp_path, 2)
    for flags in (["-v"], ["--log-level", "debug"], ["-q"], ["solve", "-vv"]):
        argv = (flags + [str(path)]) if flags[0] == "solve" else (flags + ["solve", str(path)])
        r = run(*argv)
        assert r.returncode == 0, r.stderr
    r = run("solve", str(path), "--log-level", "loud")
    assert r.returncode == 2 and "--log-level" in r.stderr


def test_progress_without_tqdm_says_so(tmp_path):
    """A stub directory shadows tqdm with an ImportError: --progress warns once; --quiet silences it."""
    stub = tmp_path / "stub"
    (stub / "tqdm").mkdir(parents=True)
    (stub / "tqdm" / "__init__.py").write_text("raise ImportError('no tqdm here')\n")
    path = problem_file(tmp_path, 2)
    env = {**ENV, "PYTHONPATH": os.pathsep.join([str(stub), str(ROOT)])}
    r = run("solve", str(path), "--progress", env=env)
    assert r.returncode == 0 and "--progress needs tqdm" in r.stderr
    assert r.stderr.count("\n") == 1
    r = run("solve", str(path), env=env)
    assert r.returncode == 0 and r.stderr == ""


def test_help_texts_match_the_code():
    from tritools.sfm.retriangulate import PROGRESS_MIN_POINTS
    from tritools.solve.batch import PROGRESS_MIN_ITEMS

    r = run("solve", "--help")
    assert f"{PROGRESS_MIN_ITEMS} problems" in " ".join(r.stdout.split())
    r = run("colmap", "--help")
    text = " ".join(r.stdout.split())
    assert f"{PROGRESS_MIN_POINTS} points" in text and f"{PROGRESS_MIN_ITEMS} problems" not in text
    assert "--workers" in text and "--scheduler" in text


def _model(tmp_path, n=60):
    from tritools.io.colmap import write_model_arrays
    from tritools.sfm.synthetic import synthetic_arrays

    arrays, _ = synthetic_arrays(n_points=n, n_images=8, camera="OPENCV", seed=2)
    return write_model_arrays(arrays, tmp_path / "in", "bin")


def _certified(out):
    return out.stdout.split(" certified globally optimal")[0].split(", ")[-1]


@pytest.mark.slow
def test_colmap_workers_give_the_same_certificates(tmp_path):
    """Theorem 1 is solved point by point, so its SDPs go through the executor the flags choose."""
    src = _model(tmp_path, 10)
    base = run("colmap", src, tmp_path / "o0", "--method", "theorem1")
    assert base.returncode == 0, base.stderr
    for n in (1, 2):
        r = run("colmap", src, tmp_path / f"o{n}", "--method", "theorem1", "--workers", n)
        assert r.returncode == 0, r.stderr
        assert _certified(r) == _certified(base)
        a = (tmp_path / "o0" / "points3D_certificates.txt").read_text()
        assert (tmp_path / f"o{n}" / "points3D_certificates.txt").read_text() == a
    r = run("colmap", src, tmp_path / "bad", "--workers", "0")
    assert r.returncode == 2 and r.stderr.strip() == "tritools: error: --workers: must be a positive integer, got 0"
    r = run("colmap", src, tmp_path / "bad", "--workers", "2", "--scheduler", "tcp://127.0.0.1:1")
    assert r.returncode == 2 and "exclude each other" in r.stderr


@pytest.mark.slow
def test_colmap_scheduler_address(tmp_path):
    pytest.importorskip("dask.distributed")
    src = _model(tmp_path, 20)
    r = run("colmap", src, tmp_path / "bad", "--scheduler", "tcp://127.0.0.1:9")   # nothing listens on port 9
    assert r.returncode == 2 and r.stderr.startswith("tritools: error: --scheduler tcp://127.0.0.1:9: cannot connect")
    assert not (tmp_path / "bad").exists()


def test_library_calls_show_no_bar_unless_asked(capfd):
    pytest.importorskip("tqdm")
    import tritools

    rng = np.random.default_rng(5)
    P = np.array([[[1.0, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 1]], [[1.0, 0, 0, 1], [0, 1, 0, 0], [0, 0, 1, 1]]])
    probs = [(P, rng.normal(scale=0.1, size=(2, 2))) for _ in range(1200)]       # above the CLI's threshold
    tritools.triangulate_many(probs)
    assert capfd.readouterr().err == ""
    tritools.triangulate_many(probs, progress="auto")       # a captured (not a terminal) stderr: no bar
    assert capfd.readouterr().err == ""
    tritools.triangulate_many(probs, progress=True)
    assert "triangulating" in capfd.readouterr().err


@pytest.mark.slow
def test_colmap_on_a_running_dask_scheduler(tmp_path):
    distributed = pytest.importorskip("dask.distributed")
    src = _model(tmp_path, 8)
    base = run("colmap", src, tmp_path / "o0", "--method", "theorem1")
    assert base.returncode == 0, base.stderr
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp",
                                  host="127.0.0.1", dashboard_address=None) as cluster:
        r = run("colmap", src, tmp_path / "o1", "--method", "theorem1", "--scheduler", cluster.scheduler_address)
        executed = sum(w.state.executed_count for w in cluster.workers.values())
    assert executed > 0                                       # the per-point SDPs ran on the cluster
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "o1" / "points3D_certificates.txt").read_text() == \
        (tmp_path / "o0" / "points3D_certificates.txt").read_text()


def test_progress_moves_per_stack_of_equal_track_lengths():
    """One chunk of points with several track lengths: the bar moves once per stack, and by all the points."""
    from tritools.sfm import RetriangulationOptions, prepare_geometry, process_chunk
    from tritools.sfm.synthetic import synthetic_arrays

    arrays, _ = synthetic_arrays(n_points=200, n_images=10, seed=4)
    updates = []

    class Bar:
        def update(self, n):
            updates.append(n)

    process_chunk(arrays, prepare_geometry(arrays), arrays.points(0, 200), RetriangulationOptions(max_delta=2), Bar())
    lengths = np.diff(arrays.track_offsets)
    assert len(updates) >= len(np.unique(lengths)) > 3 and sum(updates) == 200
