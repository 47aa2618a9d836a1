"""Helpers shared by the CLI tests: run ``tritools.cli.app.main`` in-process and write problem files."""
import json

from tritools.cli import app as cli


def run(argv, capsys):
    """(exit code, stdout, stderr) of ``tritools <argv>``."""
    rc = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def write(tmp_path, doc, name="problems.json"):
    """``doc`` (bytes, text, or a JSON-able object) written to ``tmp_path / name``."""
    p = tmp_path / name
    if isinstance(doc, bytes):
        p.write_bytes(doc)
    else:
        p.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return p


def colmap_signalled(tmp_path, signum, *extra):
    """``python -m tritools colmap IN OUT --chunk-points 2000 *extra`` on a 20,000-point model, sent ``signum`` once
    it has staged its output (at most 60 s, then 0.5 s more): ``(returncode, stderr, OUT)``.  OUT starts with the
    user's own ``notes.txt``."""
    import os
    import subprocess
    import sys
    import time

    from tritools.io.colmap import write_model_arrays
    from tritools.sfm.synthetic import synthetic_arrays

    arr, _ = synthetic_arrays(20000, 40, "OPENCV", seed=4)
    write_model_arrays(arr, tmp_path / "in", "bin")
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    p = subprocess.Popen([sys.executable, "-m", "tritools", "colmap", str(tmp_path / "in"), str(out), "--chunk-points",
                          "2000", *map(str, extra)], env=dict(os.environ, OPENBLAS_NUM_THREADS="1"),
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 60
    while time.time() < deadline and not any(n.startswith(".tritools-staging") for n in os.listdir(out)):
        time.sleep(0.05)
    time.sleep(0.5)
    p.send_signal(signum)
    _, err = p.communicate(timeout=120)
    return p.returncode, err, out
