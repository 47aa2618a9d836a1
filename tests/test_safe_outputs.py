"""Issue 24, defects 1-3: outputs lose no data.

* ``tritools colmap IN OUT`` replaces only the files it writes: whatever else OUT holds (a user's
  project.ini, notes, masks/) survives; a needed name taken by a directory exits 2; no hidden copies.
* Every writer (``solve -o``, the model files, exports) writes a temporary file beside the target and
  renames it: under a file-size limit (RLIMIT_FSIZE, in a subprocess) the old file is intact and no
  temporary file is left.
* Two writers to one OUT (concurrent processes): no failure, no leftovers, and OUT holds the files
  of one writer, never a mix.
"""
from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from tests.cli_util import write
from tests.test_cli import example4_doc
from tritools.cli.app import main
from tritools.io.atomic import DirectoryInTheWay, atomic_open, atomic_path, staged_directory
from tritools.io.colmap import read_model_arrays, write_model_arrays
from tritools.sfm import CERTIFICATES_FILE
from tritools.sfm.synthetic import synthetic_arrays

ROOT = Path(__file__).resolve().parents[1]
MODEL_FILES = ("cameras.bin", "images.bin", "points3D.bin")


def _env() -> dict:
    return dict(os.environ, PYTHONPATH=str(ROOT), OPENBLAS_NUM_THREADS="1")


def _run_limited(args, fsize: int, cwd) -> subprocess.CompletedProcess:
    """``python -m tritools ARGS`` with a file-size limit of ``fsize`` bytes (writes beyond it fail
    with EFBIG: Python ignores SIGXFSZ)."""
    def limit():
        resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))
    return subprocess.run([sys.executable, "-m", "tritools", *map(str, args)], cwd=cwd, env=_env(),
                          preexec_fn=limit, capture_output=True, text=True, timeout=300)


def _hidden(folder) -> list:
    return sorted(p.name for p in Path(folder).rglob(".*"))


@pytest.fixture()
def model_in(tmp_path):
    a, _ = synthetic_arrays(n_points=40, n_images=5, camera="PINHOLE", seed=3)
    write_model_arrays(a, tmp_path / "in", "bin")
    return tmp_path / "in"


def _user_folder(out: Path) -> dict:
    """OUT as a COLMAP user has it: a project file, notes, a masks/ subfolder."""
    (out / "masks").mkdir(parents=True)
    files = {"project.ini": "[General]\ndatabase_path=db\n", "notes.md": "keep me\n", "masks/img1.png": "PNG"}
    for name, text in files.items():
        (out / name).write_text(text)
    return files


def test_colmap_keeps_everything_else_in_out(model_in, tmp_path, capsys):
    out = tmp_path / "sparse"
    files = _user_folder(out)
    assert main(["colmap", str(model_in), str(out)]) == 0
    for name, text in files.items():
        assert (out / name).read_text() == text, name            # was deleted with exit 0 before the fix
    assert all((out / n).is_file() for n in MODEL_FILES + (CERTIFICATES_FILE,))
    assert read_model_arrays(out).n_points == 40 and _hidden(tmp_path) == []
    assert sorted(os.listdir(tmp_path)) == ["in", "sparse"]      # nothing beside OUT either


def test_colmap_refuses_a_directory_where_a_file_goes(model_in, tmp_path, capsys):
    out = tmp_path / "out"
    (out / "points3D.bin").mkdir(parents=True)
    (out / "points3D.bin" / "mine.txt").write_text("x")
    assert main(["colmap", str(model_in), str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "points3D.bin: is a directory" in err
    assert sorted(os.listdir(out)) == ["points3D.bin"] and (out / "points3D.bin" / "mine.txt").read_text() == "x"


def test_write_model_keeps_other_files_and_refuses_a_directory(model_in, tmp_path):
    a = read_model_arrays(model_in)
    out = tmp_path / "m"
    files = _user_folder(out)
    write_model_arrays(a, out, "txt")
    assert all((out / n).read_text() == t for n, t in files.items()) and _hidden(out) == []
    (out / "images.txt").unlink()
    (out / "images.txt").mkdir()
    before = (out / "cameras.txt").read_bytes()
    with pytest.raises(DirectoryInTheWay, match="images.txt: is a directory"):
        write_model_arrays(a, out, "txt")
    assert (out / "cameras.txt").read_bytes() == before and _hidden(out) == []


def test_atomic_helpers_leave_the_target_on_failure_and_name_it(tmp_path):
    target = tmp_path / "a.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError), atomic_open(target) as fh:
        fh.write("half")
        raise RuntimeError("interrupted")
    assert target.read_text() == "old" and sorted(os.listdir(tmp_path)) == ["a.txt"]
    with pytest.raises(OSError) as info, atomic_path(target) as tmp:
        raise OSError(28, "No space left on device", str(tmp))
    assert info.value.filename == str(target) and target.read_text() == "old"   # never the temporary name
    with pytest.raises(DirectoryInTheWay):
        with atomic_open(tmp_path):
            pass
    with pytest.raises(OSError) as info, staged_directory(tmp_path / "new") as stage:
        raise OSError(27, "File too large", str(stage / "points3D.bin"))
    assert info.value.filename == str(tmp_path / "new" / "points3D.bin")
    assert sorted(os.listdir(tmp_path)) == ["a.txt"]              # the folder created for the call is gone


def test_solve_output_under_a_file_size_limit_keeps_the_old_file(tmp_path):
    problems = write(tmp_path, example4_doc())
    out = tmp_path / "results.json"
    out.write_text("previous results\n" * 10)                    # 170 bytes: the new output is larger
    before = out.read_bytes()
    proc = _run_limited(["solve", problems, "--json", "-o", out], fsize=len(before) + 10, cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.count("\n") == 1 and "cannot write" in proc.stderr and str(out) in proc.stderr
    assert out.read_bytes() == before                            # was truncated in place before the fix
    assert sorted(os.listdir(tmp_path)) == ["problems.json", "results.json"]
    proc = _run_limited(["solve", problems, "--json", "-o", out], fsize=1 << 24, cwd=tmp_path)
    assert proc.returncode == 0 and json.loads(out.read_text())[0]["status"] == "optimal"


def test_colmap_under_a_file_size_limit_keeps_the_old_model(model_in, tmp_path):
    out = tmp_path / "out"
    files = _user_folder(out)
    assert main(["colmap", str(model_in), str(out), "--max-delta", "2"]) == 0
    before = {n: (out / n).read_bytes() for n in MODEL_FILES + (CERTIFICATES_FILE,)}
    limit = max(len(b) for b in before.values()) - 1          # the largest file cannot be written again
    proc = _run_limited(["colmap", model_in, out, "--max-delta", "2", "--output-type", "txt"], limit, tmp_path)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert "staging" not in proc.stderr and ".tmp-" not in proc.stderr       # names OUT's file, not a temporary one
    assert {n: (out / n).read_bytes() for n in before} == before
    assert all((out / n).read_text() == t for n, t in files.items()) and _hidden(tmp_path) == []
    assert not any((out / n).exists() for n in ("cameras.txt", "images.txt", "points3D.txt"))


_CSV = textwrap.dedent("""
    import resource, sys
    from types import SimpleNamespace
    from tritools.cli.app import CLIError, _write_dataset_csv
    from tritools.result import Status, TriangulationResult
    resource.setrlimit(resource.RLIMIT_FSIZE, (int(sys.argv[2]), int(sys.argv[2])))
    tracks = [SimpleNamespace(track_id=k, views=(0, 1, 2), n_views=3) for k in range(200)]
    results = [TriangulationResult("theorem1", Status.OPTIMAL, message="m" * 40) for _ in tracks]
    try:
        _write_dataset_csv(sys.argv[1], "seq", tracks, results, [(0.1, "own")] * len(tracks))
    except CLIError as exc:
        print(exc)
        sys.exit(2)
""")


def test_dataset_csv_under_a_file_size_limit_keeps_the_old_file(tmp_path):
    out = tmp_path / "tracks.csv"
    out.write_text("old,csv\n" * 100)
    before = out.read_bytes()
    proc = subprocess.run([sys.executable, "-c", _CSV, str(out), str(len(before) + 100)], env=_env(),
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "cannot write" in proc.stdout and str(out) in proc.stdout, proc.stderr
    assert out.read_bytes() == before and sorted(os.listdir(tmp_path)) == ["tracks.csv"]
    proc = subprocess.run([sys.executable, "-c", _CSV, str(out), str(1 << 24)], env=_env(),
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and out.read_text().count("\n") == 201


_WRITER = textwrap.dedent("""
    import sys
    from pathlib import Path
    from tritools.sfm import atomic_directory
    out, tag, n = Path(sys.argv[1]), sys.argv[2], int(sys.argv[3])
    for i in range(n):
        with atomic_directory(out) as stage:
            for name in ("cameras.bin", "images.bin", "points3D.bin"):
                (stage / name).write_text(f"{tag} {i}\\n" * 2000)
""")


def test_two_writers_to_one_out_neither_fail_nor_leave_copies(tmp_path):
    out = tmp_path / "out"
    files = _user_folder(out)
    script = tmp_path / "writer.py"
    script.write_text(_WRITER)
    procs = [subprocess.Popen([sys.executable, str(script), str(out), tag, "150"], env=_env(),
                              stderr=subprocess.PIPE, text=True) for tag in ("A", "B", "C")]
    errs = [p.communicate(timeout=300)[1] for p in procs]
    assert [p.returncode for p in procs] == [0, 0, 0], errs     # 39-74 of 600 replacements failed before
    assert _hidden(tmp_path) == [] and sorted(os.listdir(tmp_path)) == ["out", "writer.py"]
    assert all((out / n).read_text() == t for n, t in files.items())
    heads = {(out / n).read_text().split("\n", 1)[0].split()[0] for n in MODEL_FILES}
    assert len(heads) == 1                                        # the files of one writer, not a mix


def test_two_colmap_runs_into_one_out(model_in, tmp_path):
    out = tmp_path / "out"
    files = _user_folder(out)
    args = ["colmap", str(model_in), str(out), "--max-delta", "2"]
    procs = [subprocess.Popen([sys.executable, "-m", "tritools", *args], env=_env(), cwd=tmp_path,
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    errs = [p.communicate(timeout=300)[1] for p in procs]
    assert [p.returncode for p in procs] == [0, 0], errs
    assert _hidden(tmp_path) == [] and read_model_arrays(out).n_points == 40
    assert all((out / n).read_text() == t for n, t in files.items())


def test_colmap_from_oxford_keeps_everything_else_in_out(oxford_data, tmp_path, capsys):
    out = tmp_path / "sparse"
    files = _user_folder(out)
    assert main(["colmap-from-oxford", "library", str(out), "--data-dir", str(oxford_data), "--max-tracks", "20"]) == 0
    assert all((out / n).read_text() == t for n, t in files.items())   # was deleted with exit 0 before the fix
    assert read_model_arrays(out).n_points == 20 and _hidden(tmp_path) == []
    (out / "images.txt").unlink()
    (out / "images.txt").mkdir()
    assert main(["colmap-from-oxford", "library", str(out), "--data-dir", str(oxford_data)]) == 2
    assert "images.txt: is a directory" in capsys.readouterr().err and _hidden(tmp_path) == []


def test_a_killed_writer_s_staging_directory_is_swept(tmp_path):
    """A writer killed with SIGKILL cannot clean up: the next writer removes its stage (its lock is
    free); the stage of a live writer (locked) is left alone."""
    import fcntl

    from tritools.io.atomic import STAGE_MARKER, STAGING_PREFIX

    out = tmp_path / "out"
    stale = out / f"{STAGING_PREFIX}dead"
    live = out / f"{STAGING_PREFIX}live"
    mine = out / f"{STAGING_PREFIX}mine"          # a user's folder with the prefix, no marker (review 38b M3)
    for d in (stale, live, mine):
        d.mkdir(parents=True)
        (d / "points3D.bin").write_bytes(b"half")
    for d in (stale, live):
        (d / STAGE_MARKER).touch()
    fd = os.open(live, os.O_RDONLY)
    fcntl.flock(fd, fcntl.LOCK_EX)
    try:
        with staged_directory(out) as stage:
            (stage / "cameras.bin").write_bytes(b"new")
        assert not stale.exists() and live.exists()
        assert sorted(os.listdir(out)) == sorted([live.name, mine.name, "cameras.bin"])
        assert (mine / "points3D.bin").read_bytes() == b"half"
    finally:
        os.close(fd)


def test_a_user_folder_with_the_staging_prefix_is_not_a_stage(tmp_path):
    """Review 38b M3: ``tritools colmap IN OUT`` deleted OUT/.tritools-staging-mine/keep.txt (any unlocked folder with
    the prefix was swept), and a target with the prefix was written into as if it were an outer writer's stage.
    The marker file is never committed."""
    from tritools.io.atomic import STAGE_MARKER, STAGING_PREFIX

    out = tmp_path / "out"
    mine = out / f"{STAGING_PREFIX}mine"
    mine.mkdir(parents=True)
    (mine / "keep.txt").write_text("user data")
    with staged_directory(out) as stage:
        (stage / "points3D.txt").write_text("x")
    assert (mine / "keep.txt").read_text() == "user data"
    with staged_directory(mine) as stage:             # a target with the prefix: staged like any folder
        assert stage != mine
        (stage / "cameras.txt").write_text("y")
    assert sorted(os.listdir(mine)) == ["cameras.txt", "keep.txt"]
    assert not any(STAGE_MARKER in files for _, _, files in os.walk(tmp_path))


def test_special_files_are_written_directly(tmp_path, capsys):
    problems = write(tmp_path, example4_doc())
    assert main(["solve", str(problems), "--json", "-o", os.devnull]) == 0
    assert sorted(os.listdir(tmp_path)) == ["problems.json"]


def test_a_folder_that_cannot_take_a_stage_is_named_not_the_stage(model_in, tmp_path, monkeypatch, capsys):
    import tempfile

    def read_only(prefix, dir):
        raise PermissionError(13, "Permission denied", os.path.join(dir, prefix + "x1y2z3"))
    monkeypatch.setattr(tempfile, "mkdtemp", read_only)
    out = tmp_path / "out"
    out.mkdir()
    assert main(["colmap", str(model_in), str(out)]) == 2
    assert capsys.readouterr().err == f"tritools: error: {out}: Permission denied\n"


def test_a_model_written_inside_an_outer_stage_does_not_wait_for_its_own_lock(model_in, tmp_path):
    """colmap-from-oxford writes the model (itself staged) into the stage of OUT: the inner writer must
    use the outer stage, not lock it again (it held the outer writer's lock forever)."""
    import threading

    from tritools.sfm import atomic_directory

    arrays = read_model_arrays(model_in)
    out = tmp_path / "out"
    done = []

    def run():
        with atomic_directory(out) as stage:
            write_model_arrays(arrays, stage, "bin")
        done.append(True)

    t = threading.Thread(target=run, daemon=True)
    t.start()
    t.join(60)
    assert done, "writing a model inside an atomic directory deadlocked"
    assert sorted(p.name for p in out.iterdir()) == ["cameras.bin", "images.bin", "points3D.bin"]
    assert read_model_arrays(out).equals(arrays)


def test_a_symlinked_output_is_written_through_its_link(tmp_path, capsys):
    """Review 22a F4: ``solve -o link.json`` with link.json a symbolic link replaced the link by a regular file (a
    file the command did not write); the output now goes to the link's target and the link stays."""
    target = tmp_path / "real.json"
    target.write_text("old")
    link = tmp_path / "link.json"
    link.symlink_to(target)
    with atomic_open(link) as fh:
        fh.write("new")
    assert link.is_symlink() and target.read_text() == "new"
    problems = write(tmp_path, example4_doc())
    assert main(["solve", str(problems), "--json", "-o", str(link)]) == 0
    assert link.is_symlink() and json.loads(target.read_text())[0]["status"] == "optimal"
    assert sorted(os.listdir(tmp_path)) == ["link.json", "problems.json", "real.json"]
