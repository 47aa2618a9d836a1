"""Re-triangulate a COLMAP model folder into another one, streaming and atomically.

:func:`retriangulate_folder` reads the cameras and images of IN (binary or text), streams the
points in chunks (:meth:`tritools.io.colmap.formats.ModelSource.chunks`), processes each chunk
(:func:`.pipeline.process_chunk`) and appends it to the output points file and the certificate
sidecar; memory is the keypoints plus one chunk.  Everything -- the model, the sidecar, copies
of ``rigs``/``frames`` files -- is written into a staging directory inside OUT; once everything
was written each file replaces its namesake in OUT by one rename, under a lock on OUT
(:func:`atomic_directory`).  Nothing else in OUT is touched (a user's notes, masks, subfolders
stay), a failure at any point leaves OUT exactly as it was, and two runs writing to one OUT never
mix their files.  Exports (.ply/.npz) are written to temporary files and renamed into place after
the model.  The point quality (``quality``: :mod:`tritools.sfm.quality`) is applied to the staged model and
exports before anything is renamed, so a failure there too leaves OUT and the exports as they were.
"""
from __future__ import annotations

import contextlib
import functools
import logging
import os
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..io.atomic import DirectoryInTheWay, atomic_path, input_clash, new_folders, staged_directory
from ..io.colmap.formats import FORMATS, ModelWriter, open_model
from ..solve.call_limit import call_limit
from .certificates import CertificateWriter
from .pipeline import OptionError, RetriangulationOptions, prepare_geometry, process_chunk
from .retriangulate import RetriangulationReport, has_tqdm, progress_bar, skipped_cameras, skipped_images
from .robust_tracks import drop_observations, rewrite_images

__all__ = ["OutputError", "atomic_directory", "check_output", "retriangulate_folder", "FolderResult",
           "EXTRA_FILES", "EXPORT_SUFFIXES", "written_names"]

logger = logging.getLogger(__name__)
#: files of newer COLMAP versions copied unchanged when the output has the input's format.
EXTRA_FILES = {"txt": ("rigs.txt", "frames.txt"), "bin": ("rigs.bin", "frames.bin")}
EXPORT_SUFFIXES = (".ply", ".npz")


class OutputError(ValueError):
    """An output path that cannot be used (a file where a folder is needed, OUT = IN, ...)."""


@contextlib.contextmanager
def atomic_directory(target):
    """Yield a staging directory inside the folder ``target`` (created if needed); on success each
    file written into it replaces its namesake in ``target`` atomically, under a lock on ``target``;
    every other file of ``target`` is kept (:func:`tritools.io.atomic.staged_directory`).  On any
    exception ``target`` is as it was.  A name taken by a directory, or ``target`` a file:
    :class:`OutputError`."""
    try:
        with staged_directory(target) as stage:
            yield stage
    except (DirectoryInTheWay, NotADirectoryError) as exc:
        if isinstance(exc, NotADirectoryError) and exc.filename != str(target):
            raise
        raise OutputError(f"{exc.filename}: {exc.strerror}") from None


def _model_names(fmt: str) -> tuple:
    return tuple(f"{stem}.{fmt}" for stem in ("cameras", "images", "points3D"))


def written_names() -> tuple:
    """Every file name :func:`retriangulate_folder` (with ``quality``) may write into OUT, in either format: the
    model, the certificate sidecar, the copied ``rigs``/``frames`` files and the quality file."""
    from .certificates import CERTIFICATES_FILE
    from .quality import QUALITY_FILE

    return tuple(n for fmt in ("bin", "txt") for n in _model_names(fmt) + EXTRA_FILES[fmt]) + \
        (CERTIFICATES_FILE, QUALITY_FILE)


def _check_names(out_dir, fmt_out: str, in_dir, quality=None) -> None:
    """Refuse (:class:`OutputError`) before any work when a file the command writes into OUT is
    the name of a directory there (it is never removed), or when OUT holds a file of another model that this
    run would leave beside the new one (:func:`_stale_files`)."""
    from .certificates import CERTIFICATES_FILE

    out = Path(out_dir)
    names = _model_names(fmt_out) + (CERTIFICATES_FILE,) + EXTRA_FILES[fmt_out]
    for name in names:
        if (out / name).is_dir() and (name not in EXTRA_FILES[fmt_out] or (Path(in_dir) / name).is_file()):
            raise OutputError(f"{out / name}: is a directory (refusing to replace it with a file)")
    stale = _stale_files(out, fmt_out, Path(in_dir), quality)
    if stale:
        raise OutputError(f"{out / stale[0][0]}: {stale[0][1]}; it would stay beside the new model (this command "
                          "never deletes a file it did not write): remove it or choose another OUT_DIR")


def _stale_files(out: Path, fmt_out: str, in_dir: Path, quality) -> list:
    """(name, why) of the files in OUT that describe another model and that this run would neither replace nor
    remove (review 27a F1): ``rigs``/``frames`` files of the output's format that IN does not have (COLMAP reads
    them with the new model and refuses it: an image in no frame), and a quality file when this run writes none
    (it lists points removed from another model)."""
    from .quality import QUALITY_FILE

    out_stale = [(n, "rigs/frames file of another model (IN has none)") for n in EXTRA_FILES[fmt_out]
                 if (out / n).is_file() and not (in_dir / n).is_file()]
    if (quality is None or not quality.active) and (out / QUALITY_FILE).is_file():
        out_stale.append((QUALITY_FILE, "the point quality of another run (this run has no quality filter)"))
    return out_stale


def _other_model_notes(out_dir, fmt_out: str) -> list:
    """A note when OUT already holds a model of the other format (kept as it was: COLMAP and
    :func:`~tritools.io.colmap.formats.open_model` read the binary files first)."""
    other = "txt" if fmt_out == "bin" else "bin"
    found = [n for n in _model_names(other) if (Path(out_dir) / n).is_file()]
    return [f"{', '.join(found)} in {out_dir} kept as they were (a {other} model; COLMAP reads .bin files first; "
            f"points3D_certificates.txt there now describes the new {fmt_out} model, not them)"] if found else []


#: a quaternion whose norm differs from 1 by more than this gets a note (:func:`_quaternion_notes`)
QUATERNION_NORM_RTOL = 1e-6


def _quaternion_notes(arrays) -> list:
    """A note when an image's quaternion is not a unit one: tritools normalises it (the rotation it stands for),
    COLMAP / pycolmap use it as stored -- a scaled, not orthogonal matrix -- so the two disagree on the pose
    (review 27a F9: ERROR 0.42 px apart at |q| = 1.001); the model is written back with the quaternion as read."""
    norms = np.linalg.norm(np.asarray(arrays.image_qvec, float).reshape(-1, 4), axis=1)
    off = np.abs(norms - 1.0) > QUATERNION_NORM_RTOL
    if not off.any():
        return []
    k = int(np.argmax(np.abs(norms - 1.0)))
    return [f"{int(off.sum())} image quaternion(s) are not unit ones (image {int(arrays.image_ids[k])}: |q| = "
            f"{norms[k]:.9g}): normalised here, whereas COLMAP uses them as stored; poses, reprojection errors and "
            "certificates refer to the normalised rotations"]


def _spaced_name_notes(arrays, fmt_in: str, fmt_out: str) -> list:
    """A note when a binary model's image names hold whitespace and the output is text: COLMAP's (and pycolmap's)
    text reader takes the first word of a name, so the written text model would link other image files (review 29b
    F12).  (A text input had the same names already: no note; tritools' own text reader keeps the whole name.)"""
    if fmt_out != "txt" or fmt_in == "txt":
        return []
    spaced = [(i, n) for i, n in zip(arrays.image_ids.tolist(), arrays.image_names) if len(n.split()) > 1]
    if not spaced:
        return []
    i, n = spaced[0]
    return [f"{len(spaced)} image name(s) contain whitespace (image {i}: {n!r}): COLMAP's text reader takes only the "
            f"first word ({n.split()[0]!r}); keep the binary format (--output-type bin) to keep them"]


def _timed(iterator, timings: dict, key: str):
    """Iterate, adding the time spent producing each item to ``timings[key]``."""
    while True:
        t0 = time.perf_counter()
        item = next(iterator, None)
        timings[key] += time.perf_counter() - t0
        if item is None:
            return
        yield item


def check_output(in_dir, out_dir, exports=()) -> None:
    """Refuse unusable outputs before any work (:class:`OutputError`): OUT a file, OUT = IN, OUT
    containing IN (replacing OUT would delete the input), OUT or an export inside IN (IN is never modified), an
    export that is a directory or has another suffix than .ply/.npz."""
    dst = Path(out_dir)
    if dst.exists() and not dst.is_dir():
        raise OutputError(f"OUT_DIR {out_dir}: exists and is not a directory")
    blocker = _file_in_the_way(dst.parent)
    if blocker is not None:
        raise OutputError(f"OUT_DIR {out_dir}: {blocker} is not a directory")
    clash = input_clash(out_dir, "OUT_DIR", [("IN_DIR", in_dir)], folder=True)   # the rule of every command
    if clash:
        raise OutputError(clash)
    for e in exports:
        p = Path(e)
        if p.suffix.lower() not in EXPORT_SUFFIXES:
            raise OptionError("export", f"{e}: the file name must end with .ply or .npz")
        if p.is_dir():
            raise OptionError("export", f"{e}: is a directory")
        blocker = _file_in_the_way(p.parent)
        if blocker is not None:
            raise OptionError("export", f"{e}: {blocker} is not a directory")
        clash = input_clash(e, "export", [("IN_DIR", in_dir)])
        if clash:
            raise OutputError(clash)


def _file_in_the_way(folder: Path) -> Path | None:
    """The nearest existing ancestor of ``folder`` (itself included) when it is not a directory: a folder that
    cannot be created there (``--export afile/x.ply`` with ``afile`` a file)."""
    for p in (folder, *folder.parents):
        if os.path.lexists(p):
            return None if p.is_dir() else p
    return None


@dataclass(frozen=True)
class FolderResult:
    """What :func:`retriangulate_folder` did: the report, where things went, and timings in seconds
    (``open``: cameras and images read; ``geometry``: undistortion; ``read``: points read and
    checked; ``solve``: processing; ``write``; ``total``)."""
    report: RetriangulationReport
    out_dir: Path
    input_format: str
    output_format: str
    certificates: Path
    exports: tuple = ()
    copied: tuple = ()
    notes: tuple = ()
    timings: dict = field(default_factory=dict)
    quality: object = None          # the PointQuality of ``quality`` (tritools.sfm.quality), or None


def _within_total_limit(run):
    """``run(in_dir, out_dir, options, ...)`` within ``options.solver.total_time_limit``, the whole run's limit
    (:mod:`tritools.solve.call_limit`: the points not solved by then get status ``time_limit``)."""
    @functools.wraps(run)
    def limited(in_dir, out_dir, options: RetriangulationOptions | None = None, **kw):
        if options is not None and not isinstance(options, RetriangulationOptions):
            raise TypeError(f"options must be a RetriangulationOptions, got {type(options).__name__}")
        with call_limit((options or RetriangulationOptions()).solver.total_time_limit):
            return run(in_dir, out_dir, options, **kw)
    return limited


@_within_total_limit
def retriangulate_folder(in_dir, out_dir, options: RetriangulationOptions | None = None, *,
                         input_format: str | None = None, output_format: str | None = None,
                         exports=(), quality=None) -> FolderResult:
    """Re-triangulate the model in ``in_dir`` into ``out_dir`` (see the module docstring).

    ``input_format`` None detects it; ``output_format`` None keeps it; ``exports``: .ply / .npz
    paths written with the certificate fields (:mod:`tritools.io.export`); ``quality``: a
    :class:`~tritools.sfm.quality.QualityOptions` applied to the staged output before anything is committed
    (:func:`~tritools.sfm.quality.apply_quality_staged`: a failure there leaves OUT_DIR and the exports as they
    were)."""
    options = options or RetriangulationOptions()
    t_start = time.perf_counter()
    for name, fmt in (("input_format", input_format), ("output_format", output_format)):
        if fmt is not None and fmt not in FORMATS:          # (a KeyError from deep inside, review 29b F14)
            raise OptionError(name, f"must be one of {', '.join(FORMATS)} or None, got {fmt!r}")
    for name, value in (("in_dir", in_dir), ("out_dir", out_dir)):
        if not isinstance(value, (str, os.PathLike)):
            raise TypeError(f"retriangulate_folder {name} must be a path (str or os.PathLike), got "
                            f"{type(value).__name__}")
    check_output(in_dir, out_dir, exports)
    timings = dict.fromkeys(("open", "geometry", "read", "solve", "write"), 0.0)
    t0 = time.perf_counter()
    src = open_model(in_dir, input_format)
    fmt_out = output_format or src.format
    timings["open"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    geom = prepare_geometry(src.arrays, options.strict)
    timings["geometry"] = time.perf_counter() - t0
    # the total only when a bar may be shown (a text model costs one quick pass over points3D.txt)
    want = options.progress is True or (options.progress == "auto" and has_tqdm())
    bar = progress_bar(src.count_points() if want else None, options.progress)
    ids, results, xyz, rgb = [], [], [], []
    removed: list = []                      # global keypoint indices of observations removed as outliers
    copied, notes = [], _other_model_notes(out_dir, fmt_out) + _quaternion_notes(src.arrays) + \
        _spaced_name_notes(src.arrays, src.format, fmt_out)
    _check_names(out_dir, fmt_out, src.folder, quality)
    try:
        with _export_stack(exports) as staged_exports, atomic_directory(out_dir) as tmp:
            writer = ModelWriter(src.arrays, tmp, fmt_out)
            certs = CertificateWriter(tmp, options.method, options.path)
            try:
                for chunk in _timed(src.chunks(options.chunk_points), timings, "read"):
                    t0 = time.perf_counter()
                    res = process_chunk(src.arrays, geom, chunk, options, bar)
                    timings["solve"] += time.perf_counter() - t0
                    t0 = time.perf_counter()
                    if res.keep_obs is not None:
                        chunk = drop_observations(src.arrays, chunk, res.keep_obs, removed)
                    writer.write_points(chunk, res.xyz, res.error)
                    certs.write(chunk.ids, res)
                    timings["write"] += time.perf_counter() - t0
                    ids.append(chunk.ids)
                    results.append(res)
                    if exports:
                        xyz.append(res.xyz)
                        rgb.append(chunk.rgb)
                t0 = time.perf_counter()
                writer.close()
                if removed:
                    rewrite_images(src.arrays, tmp, fmt_out, np.concatenate(removed))
                sidecar = certs.close()
            except BaseException:
                writer.abort()
                certs.abort()
                raise
            _copy_extra_files(src.folder, tmp, fmt_out, copied, notes)
            report = RetriangulationReport.from_chunks(options, ids, results, skipped_cameras(src.arrays, geom),
                                                       skipped_images(src.arrays, geom))
            staged = _stage_exports(staged_exports, exports, xyz, rgb, report)
            point_quality = _staged_quality(tmp, quality, staged)
            timings["write"] += time.perf_counter() - t0
    finally:
        if bar is not None:
            bar.close()
    timings["total"] = time.perf_counter() - t_start
    out = Path(out_dir)
    logger.info("re-triangulated %d points into %s in %.2f s", report.n_points, out, timings["total"])
    return FolderResult(report, out, src.format, fmt_out, out / sidecar.name, tuple(Path(e) for e in exports),
                        tuple(copied), tuple(notes), timings, point_quality)


def _staged_quality(stage: Path, quality, staged_exports: list):
    """The :class:`~tritools.sfm.quality.PointQuality` of ``quality`` applied to the staged model and exports
    (:func:`~tritools.sfm.quality.apply_quality_staged`), or None without ``quality``."""
    if quality is None or not quality.active:
        return None
    from .quality import apply_quality_staged

    return apply_quality_staged(stage, quality, staged_exports)


def _copy_extra_files(folder: Path, tmp: Path, fmt_out: str, copied: list, notes: list) -> None:
    """Copy the input model's extra files of the output format (:data:`EXTRA_FILES`) into the staged output;
    a note for each one of the other format."""
    for fmt, names in EXTRA_FILES.items():
        for name in names:
            if (folder / name).is_file():
                if fmt == fmt_out:
                    shutil.copyfile(folder / name, tmp / name)
                    copied.append(name)
                else:
                    notes.append(f"{name} not copied: the output is a {fmt_out} model")


@contextlib.contextmanager
def _export_stack(exports):
    """The :class:`contextlib.ExitStack` of the staged exports (:func:`_stage_exports`), with the exports' missing
    folders created first: entered before OUT's own stage, they are removed again (while empty) after it when
    the run fails, so that a parent shared with OUT goes too."""
    with contextlib.ExitStack() as stack:
        for e in exports:
            stack.enter_context(new_folders(Path(e).parent))
        yield stack


def _stage_exports(stack: contextlib.ExitStack, exports, xyz: list, rgb: list, report) -> list:
    """Write the .ply / .npz exports of the points (:mod:`tritools.io.export`) to staged paths of ``stack``:
    renamed into place after the model (the stack closes last).  Returns the staged paths."""
    from ..io.export import export_points

    all_xyz = np.concatenate(xyz) if xyz else np.zeros((0, 3))
    all_rgb = np.concatenate(rgb) if rgb else np.zeros((0, 3), np.uint8)
    out = []
    for e in exports:
        target = Path(e)
        staged = stack.enter_context(atomic_path(target))
        export_points(staged, all_xyz, all_rgb, report, fmt=target.suffix.lower()[1:])
        out.append(staged)
    return out
