"""Review 11 F3/F4 and the bad-input campaign of wave 12: the CLI never writes over its input, words ``--robust``
errors once, prints one line on exit 3, and leaves nothing behind when it fails.

* F3: ``tritools solve F.json -o F.json`` replaced its input.  Every command that writes a file checks it with one
  rule (:func:`tritools.io.atomic.input_clash`, that of ``tritools colmap``'s OUT_DIR = IN_DIR), also through
  symlinks, hard links, ``..`` and stdin; checked against the bytes of the input, not the code's own output.
* F4: ``--robust`` had two wordings (``solve``: ``--robust: must``, ``colmap``: ``--robust must``) and exit 3
  printed two warning lines.
* Campaign: a ``--keypoint-radii`` file that fails only after the model is solved left a written model and
  exports behind exit 2; a failed write on a read-only file system named the temporary file (its cleanup's
  EROFS replaced the error).
"""
from __future__ import annotations

import errno
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.cli_util import run, write
from tests.test_cli import example4_doc
from tritools.io.atomic import TEMP_PREFIX, atomic_open, input_clash, new_folders, same_file
from tritools.io.colmap.formats import write_model_arrays
from tritools.sfm.synthetic import synthetic_arrays

ROOT = Path(__file__).resolve().parents[1]


def _one_error(err: str) -> str:
    assert err.count("\n") == 1 and err.startswith("tritools: error: "), err
    assert "Traceback" not in err
    return err


def _files(folder: Path) -> dict:
    """Every file under ``folder`` with its bytes (what a command may not change when it fails)."""
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture
def problem(tmp_path) -> Path:
    return write(tmp_path, example4_doc(), "F.json")


@pytest.fixture
def model(tmp_path) -> Path:
    a, _ = synthetic_arrays(n_points=12, n_images=5, camera="PINHOLE", seed=4)
    write_model_arrays(a, tmp_path / "in", "txt")
    return tmp_path / "in"


# ----------------------------------------------------------------------------- F3: outputs never inputs
def test_same_file_and_input_clash_follow_links(tmp_path):
    f = tmp_path / "a.json"
    f.write_text("{}")
    (tmp_path / "sym.json").symlink_to(f)
    os.link(f, tmp_path / "hard.json")
    (tmp_path / "sub").mkdir()
    for alias in (f, tmp_path / "sym.json", tmp_path / "hard.json", tmp_path / "sub" / ".." / "a.json"):
        assert same_file(alias, f), alias
        assert input_clash(alias, "--output", [("FILE", f)]) == \
            f"--output must differ from FILE {f} (an input is never overwritten)"
    assert not same_file(tmp_path / "new.json", f)                    # not written yet: never an input
    assert input_clash(tmp_path / "new.json", "--output", [("FILE", f)]) is None
    assert not same_file("/dev/null", "/dev/null")                     # special files are written, not replaced
    # a folder output: the folder itself, or one that contains the input
    assert "must differ from IN_DIR" in input_clash(tmp_path / "sub", "OUT_DIR", [("IN_DIR", tmp_path / "sub")],
                                                    folder=True)
    assert "contains IN_DIR" in input_clash(tmp_path, "OUT_DIR", [("IN_DIR", tmp_path / "sub")], folder=True)
    assert input_clash(tmp_path, "OUT_DIR", [("IN_DIR", tmp_path / "sub")]) is None      # a file output
    # inside an input folder (review 29b F3: IN_DIR is never modified)
    assert "is inside IN_DIR" in input_clash(tmp_path / "sub", "OUT_DIR", [("IN_DIR", tmp_path)], folder=True)
    assert "is inside IN_DIR" in input_clash(tmp_path / "sub" / "x.ply", "export", [("IN_DIR", tmp_path)])
    assert input_clash(tmp_path / "sub" / "x.ply", "export", [("IN_DIR", tmp_path / "other")]) is None


@pytest.mark.parametrize("alias", ["same", "symlink", "hardlink", "dotdot"])
def test_solve_refuses_to_write_over_its_input(problem, tmp_path, capsys, alias):
    """F3: exit 2 before any work, one line naming --output, the input's bytes unchanged, nothing left."""
    out = {"same": problem, "symlink": tmp_path / "link.json", "hardlink": tmp_path / "hard.json",
           "dotdot": tmp_path / "d" / ".." / problem.name}[alias]
    if alias == "symlink":
        out.symlink_to(problem)
    elif alias == "hardlink":
        os.link(problem, out)
    elif alias == "dotdot":
        (tmp_path / "d").mkdir()
    before = _files(tmp_path)
    for extra in ([], ["--json"]):
        rc, stdout, err = run(["solve", problem, "-o", out] + extra, capsys)
        assert rc == 2 and stdout == ""
        assert f"--output must differ from FILE {problem}" in _one_error(err)
    assert _files(tmp_path) == before


def test_solve_output_elsewhere_is_written(problem, tmp_path, capsys):
    """The check refuses only the input: another file, even beside it or through a symlink to a new name, is
    written as before."""
    rc, _, err = run(["solve", problem, "-o", tmp_path / "R.txt", "--time-limit", "20"], capsys)
    assert rc == 0, err
    assert (tmp_path / "R.txt").read_text().startswith("name")


@pytest.mark.skipif(not os.path.isdir("/proc/self/fd"), reason="needs /proc/self/fd (Linux)")
def test_an_output_that_is_a_link_to_a_pipe_is_written_into_the_pipe():
    """``tritools solve f.json -o /dev/stdout | head`` (33a L2): /dev/stdout -> /proc/self/fd/1 -> ``pipe:[N]``, a
    link that resolves to no path; the pipe is written as the special file it is."""
    r, w = os.pipe()
    try:
        with atomic_open(f"/proc/self/fd/{w}", "w") as fh:
            fh.write("through the pipe\n")
        assert os.read(r, 100) == b"through the pipe\n"
    finally:
        os.close(r)
        os.close(w)


def test_solve_refuses_stdin_read_from_the_output_file(problem, tmp_path):
    """``tritools solve - -o F.json < F.json``: stdin is the output file (a subprocess: stdin is fd 0)."""
    data = problem.read_bytes()
    with open(problem, "rb") as stdin:
        run_ = subprocess.run([sys.executable, "-m", "tritools", "solve", "-", "-o", str(problem)], stdin=stdin,
                              capture_output=True, text=True, cwd=ROOT, timeout=120,
                              env={**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1"})
    assert run_.returncode == 2 and "--output must differ from stdin" in _one_error(run_.stderr)
    assert problem.read_bytes() == data


def test_colmap_refuses_out_dir_that_is_in_dir_through_a_symlink(model, tmp_path, capsys):
    (tmp_path / "alias").symlink_to(model, target_is_directory=True)
    before = _files(tmp_path)
    rc, _, err = run(["colmap", model, tmp_path / "alias", "--max-delta", "2"], capsys)
    assert rc == 2 and "OUT_DIR must differ from IN_DIR" in _one_error(err)
    assert _files(tmp_path) == before


def test_colmap_refuses_an_export_over_its_keypoint_radii_file(model, tmp_path, capsys):
    radii = tmp_path / "radii.ply"                      # a radius file may have any name
    radii.write_text("# IMAGE_ID POINT2D_IDX RADIUS\n")
    (tmp_path / "alias.ply").symlink_to(radii)
    before = _files(tmp_path)
    rc, _, err = run(["colmap", model, tmp_path / "out", "--keypoint-radii", radii, "--keypoint-radius", "1",
                      "--export", tmp_path / "alias.ply"], capsys)
    assert rc == 2 and f"--export must differ from --keypoint-radii {radii}" in _one_error(err)
    assert _files(tmp_path) == before and not (tmp_path / "out").exists()


@pytest.fixture
def house(oxford_data, tmp_path) -> Path:
    """A copy of the house sequence (a refused write must not be able to touch the shared data)."""
    shutil.copytree(Path(oxford_data) / "house", tmp_path / "data" / "house")
    return tmp_path / "data"


def test_dataset_csv_and_plot_out_refuse_a_data_file(house, tmp_path, capsys):
    target = house / "house" / "house.nview-corners"
    before = _files(house)
    rc, _, err = run(["dataset", "house", "--data-dir", house, "--limit", "1", "--csv", target], capsys)
    assert rc == 2 and f"--csv must differ from the data file {target}" in _one_error(err)
    pytest.importorskip("matplotlib")
    (tmp_path / "plot.png").symlink_to(target)
    rc, _, err = run(["plot-dataset", "house", "--data-dir", house, "--limit", "1", "--out", tmp_path / "plot.png"],
                     capsys)
    assert rc == 2 and f"--out must differ from the data file {target}" in _one_error(err)
    assert _files(house) == before


def test_colmap_refuses_to_write_its_keypoint_radii_file_into_out(model, tmp_path, capsys):
    """A radius file kept in OUT_DIR under a name the command writes (points3D_uncertainty.txt) would be read,
    then replaced by the run's own file."""
    out = tmp_path / "out"
    out.mkdir()
    radii = out / "points3D_uncertainty.txt"
    radii.write_text("# IMAGE_ID POINT2D_IDX RADIUS\n")
    before = _files(tmp_path)
    rc, _, err = run(["colmap", model, out, "--keypoint-radii", radii, "--keypoint-radius", "1"], capsys)
    assert rc == 2 and f"OUT_DIR/points3D_uncertainty.txt must differ from --keypoint-radii {radii}" in \
        _one_error(err)
    assert _files(tmp_path) == before
    (out / "mine.txt").write_text("# IMAGE_ID POINT2D_IDX RADIUS\n")       # any other name in OUT_DIR is fine
    rc, _, err = run(["colmap", model, out, "--keypoint-radii", out / "mine.txt", "--keypoint-radius", "1",
                      "--max-delta", "2"], capsys)
    assert rc == 0, err
    assert (out / "points3D_uncertainty.txt").read_text() != "# IMAGE_ID POINT2D_IDX RADIUS\n"


# ----------------------------------------------------------------------------- F4: one --robust rule and wording
@pytest.mark.parametrize("value, expect", [
    ("0", "--robust: must be a positive threshold in pixels, got 0.0"),
    ("-1", "--robust: must be a positive threshold in pixels, got -1.0"),
    ("nan", "--robust: must be a positive threshold in pixels, got nan"),
    ("-inf", "--robust: must be a positive threshold in pixels, got -inf"),
    ("1e-300", "--robust: must be at least 1.5e-154 pixels (its square underflows), got 1e-300"),
    ("abc", "argument --robust: invalid float value: 'abc'"),
    ("1,2", "argument --robust: invalid float value: '1,2'"),
])
def test_robust_errors_are_worded_once_for_solve_and_colmap(problem, model, tmp_path, capsys, value, expect):
    lines = []
    for argv in (["solve", problem], ["colmap", model, tmp_path / "out"]):
        rc, stdout, err = run(argv + [f"--robust={value}"], capsys)
        assert rc == 2 and stdout == ""
        # argparse's errors name the subcommand and its --help
        line = _one_error(err).removeprefix("tritools: error: ").removeprefix(argv[0] + ": ")
        lines.append(line.replace(f" (see 'tritools {argv[0]} --help')", ""))
    assert lines[0] == lines[1] and expect in lines[0], lines
    assert not (tmp_path / "out").exists()


def test_colmap_field_errors_name_the_flag_with_a_colon(model, tmp_path, capsys):
    """The one form ``FLAG: reason`` of every flag (it was ``--min-track-length must ...`` beside ``--delta: ...``)."""
    for flags, expect in ((["--min-track-length", "1"], "--min-track-length: must be an integer >= 2, got 1"),
                          (["--keypoint-radius", "inf"], "--keypoint-radius: must be a finite number, got inf"),
                          (["--max-uncertainty", "1"], "--max-uncertainty: needs keypoint_radius")):
        rc, _, err = run(["colmap", model, tmp_path / "out"] + flags, capsys)
        assert rc == 2 and expect in _one_error(err), err
    rc, _, err = run(["colmap-from-oxford", "house", tmp_path / "o", "--max-tracks", "0"], capsys)
    assert rc == 2 and "--max-tracks: must be an integer >= 1, got 0" in _one_error(err)
    assert not (tmp_path / "out").exists() and not (tmp_path / "o").exists()


def test_exit_3_prints_one_warning_line(tmp_path, capsys):
    """F4: a camera with focal 0 leaves its observations out: exit 3 and one line on stderr (the library's warning
    per camera only from -v on)."""
    from tests.test_colmap import synthetic_model
    from tritools.io.colmap import Camera, Model, write_text_model

    m, _ = synthetic_model(n_points=6, noise_px=0.5, seed=3)
    cams = dict(m.cameras)
    cams[3] = Camera(3, "PINHOLE", 640, 480, (0.0, 800.0, 320.0, 240.0))
    write_text_model(Model(cams, m.images, m.points3D), tmp_path / "in")
    rc, _, err = run(["colmap", tmp_path / "in", tmp_path / "o", "--max-delta", "2"], capsys)
    assert rc == 3
    assert err.count("\n") == 1 and err.startswith("tritools: warning: 1 camera(s) could not be used (PINHOLE): "), err
    rc, _, err = run(["colmap", tmp_path / "in", tmp_path / "o2", "--max-delta", "2", "-v"], capsys)
    assert rc == 3 and "tritools: warning: camera 3 (PINHOLE) skipped: focal length fx = 0.0 must be > 0" in err
    rc, _, err = run(["colmap", tmp_path / "in", tmp_path / "o3", "--max-delta", "2", "-q"], capsys)
    assert rc == 3 and err == ""


# ----------------------------------------------------------------------------- campaign: nothing left on failure
@pytest.mark.parametrize("radii", ["999 0 1.5\n",            # unknown image: found only when the quality is computed
                                   "1 0 1.5\n"])             # other observations without a radius and no default
def test_a_failing_quality_step_leaves_out_and_exports_as_they_were(model, tmp_path, capsys, radii):
    """The point quality ran after the model was committed: exit 2 left a new model and exports behind.  Now it
    runs on the staged output: OUT keeps exactly what it held, no export appears."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.md").write_text("keep me\n")
    (tmp_path / "r.txt").write_text(radii)
    before = _files(tmp_path)
    rc, _, err = run(["colmap", model, out, "--max-delta", "2", "--keypoint-radii", tmp_path / "r.txt",
                      "--export", tmp_path / "e.ply", "--export", out / "e.npz"], capsys)
    assert rc == 2 and str(tmp_path / "r.txt") in _one_error(err)
    assert _files(tmp_path) == before
    assert not [p for p in tmp_path.rglob("*") if p.name.startswith((TEMP_PREFIX, ".tritools-staging-"))]


def test_a_failing_run_removes_the_folders_it_created(model, tmp_path, capsys):
    """OUT_DIR and the exports' folders are created if missing; a failed run removed only OUT_DIR's last folder and
    left the others (and the exports' folders) behind.  Now every folder it created goes, folders it found stay."""
    (tmp_path / "r.txt").write_text("999 0 1.5\n")                  # fails after the solve, before the commit
    (tmp_path / "kept").mkdir()
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    rc, _, err = run(["colmap", model, tmp_path / "x" / "y" / "out", "--max-delta", "2", "--keypoint-radii",
                      tmp_path / "r.txt", "--export", tmp_path / "x" / "e" / "f" / "e.ply",
                      "--export", tmp_path / "kept" / "g" / "e.npz"], capsys)
    assert rc == 2 and "unknown IMAGE_ID 999" in _one_error(err)
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before
    with pytest.raises(RuntimeError):
        with new_folders(tmp_path / "a" / "b"):
            (tmp_path / "a" / "b" / "c").mkdir()                     # not empty: kept, and so its parents
            raise RuntimeError
    assert (tmp_path / "a" / "b" / "c").is_dir()
    with new_folders(tmp_path / "n" / "m"):                          # success: the folders stay
        pass
    assert (tmp_path / "n" / "m").is_dir()


def test_quality_in_the_stage_still_writes_the_quality_and_exports(model, tmp_path, capsys):
    """The staged quality step writes what the committed one wrote: the uncertainty file, the filtered model and
    the exports with the quality columns (the points removed by the filter are gone from both)."""
    from tritools.io.colmap import read_model_arrays
    from tritools.io.export import read_npz

    rc, out, err = run(["colmap", model, tmp_path / "out", "--max-delta", "2", "--keypoint-radius", "1",
                        "--min-angle", "120", "--export", tmp_path / "e.npz"], capsys)
    assert rc == 0, err
    assert (tmp_path / "out" / "points3D_uncertainty.txt").is_file()
    kept = read_model_arrays(tmp_path / "out").n_points
    assert 0 < kept < 12                                                   # the filter removed some points
    cols = read_npz(tmp_path / "e.npz")
    assert len(cols["point3D_id"]) == kept and "radius" in cols and "kept" in cols


def test_a_write_failure_names_the_target_not_the_temporary_file(tmp_path, monkeypatch):
    """On a read-only file system the cleanup's unlink of the never-created temporary file raised EROFS, which
    replaced the error and named ``.tmp-...``; now the error names the target."""
    import tritools.io.atomic as atomic

    def refuse(path, *a, **k):
        raise OSError(errno.EROFS, "Read-only file system", str(path))

    monkeypatch.setattr(atomic.os, "unlink", refuse)          # as unlink behaves on a read-only mount
    real_open = open

    def ro_open(path, mode="r", *a, **k):
        if "x" in mode or "w" in mode:
            raise OSError(errno.EROFS, "Read-only file system", str(path))
        return real_open(path, mode, *a, **k)

    monkeypatch.setattr("builtins.open", ro_open)
    with pytest.raises(OSError) as info:
        with atomic_open(tmp_path / "x.txt", "w") as fh:
            fh.write("x")
    assert info.value.errno == errno.EROFS and info.value.filename == str(tmp_path / "x.txt")
