"""Atomic file output: the one rule every tritools writer follows.

A file is never written in place.  :func:`atomic_path` (for libraries that write to a path:
``savefig``, ``np.save``) and :func:`atomic_open` (a file object) write to a temporary file in the
target's own directory (``.tmp-<hex>-<name>``: same file system, same suffix), flush it to disk
(``fsync``) and rename it over the target (``os.replace``, atomic on POSIX), then sync the
directory.  A failure at any point (disk full, file-size limit, an interrupt) removes the temporary
file and leaves the target exactly as it was; an OSError names the target, never the temporary file.

:func:`staged_directory` writes several files into a folder the same way: the caller writes into a
hidden staging directory inside the folder, and on success each file replaces its namesake in the
folder by one rename, under an advisory lock on the folder (:func:`locked_directory`, ``fcntl.flock``)
so that two writers to one folder never interleave their files.  Nothing else in the folder is touched.
Each writer holds a lock on its own stage; a stage whose lock is free was left by a writer that was
killed (SIGKILL) and is removed by the next writer.

:func:`input_clash` is the one rule that keeps a command from writing over its own input: an output is
refused when it is one of the inputs (the same file: through symlinks, hard links, bind mounts), or, for
an output folder, when it contains one.  Every command checks its outputs with it before any work.
"""
from __future__ import annotations

import contextlib
import os
import shutil
import stat
import tempfile
import threading
import uuid
from pathlib import Path

__all__ = ["atomic_path", "atomic_open", "naming_errors", "staged_directory", "locked_directory", "DirectoryInTheWay",
           "same_file", "input_clash", "new_folders", "TEMP_PREFIX", "STAGING_PREFIX"]

#: prefix of the temporary file beside a target.
TEMP_PREFIX = ".tmp-"
#: prefix of the staging directory inside a folder written by :func:`staged_directory`.
STAGING_PREFIX = ".tritools-staging-"
#: the file every stage holds from its creation (never committed): only a folder holding it is a stage that a later
#: writer may sweep or write into -- a user's folder that merely starts with the prefix is not (review 38b M3).
STAGE_MARKER = ".tritools-stage"


class DirectoryInTheWay(IsADirectoryError):
    """A file must be written where a directory of that name exists (never removed)."""

    def __init__(self, path):
        super().__init__(21, "is a directory (refusing to replace it with a file)", str(path))

    def __str__(self) -> str:
        return f"{self.filename}: {self.strerror}"


def same_file(a, b) -> bool:
    """True when the paths ``a`` and ``b`` both exist and name one file or folder: the same device and
    inode (:func:`os.path.samefile`), so also through symlinks, hard links and bind mounts.  A special file
    (``/dev/stdout``, a FIFO: written directly, never replaced) is never the same as anything."""
    try:
        if stat.S_ISCHR(os.stat(a).st_mode) or stat.S_ISFIFO(os.stat(a).st_mode):
            return False
        return os.path.samefile(a, b)
    except (OSError, ValueError):       # a path that does not exist (yet), or cannot be a path (NUL)
        return False


def _contains(folder, path) -> bool:
    """True when the existing folder ``folder`` is a parent (at any depth) of the existing ``path``."""
    return os.path.exists(path) and inside(path, folder)


def inside(path, folder) -> bool:
    """True when ``path`` (existing or not) lies inside the existing folder ``folder``, at any depth, after
    resolving symbolic links."""
    try:
        parents = Path(path).resolve(strict=False).parents
    except (OSError, RuntimeError, ValueError):
        return False
    return any(same_file(folder, p) for p in parents if os.path.lexists(p))


def input_clash(output, output_name: str, inputs, folder: bool = False) -> str | None:
    """Why the command may not write ``output`` (named ``output_name`` in the message: a flag such as
    ``--output``, or ``OUT_DIR``), or None when it may.

    ``inputs``: ``(name, path)`` pairs of what the command reads.  The output is refused when it is one of
    them (:func:`same_file`); with ``folder`` (an output folder, whose files are replaced) also when it
    contains one; and an output inside an input *folder* (``tritools colmap``'s IN_DIR, "never modified": review
    29b F3, an export replaced a file there).  The one wording of the rule "a command never writes over its input".
    """
    for name, path in inputs:
        if same_file(output, path):
            return f"{output_name} must differ from {name} {path} (an input is never overwritten)"
        if folder and _contains(output, path):
            return f"{output_name} {output} contains {name} {path}: outputs are kept out of the input's folders"
        if os.path.isdir(path) and inside(output, path):
            return f"{output_name} {output} is inside {name} {path}: outputs are kept out of the input's folders"
    return None


def _make_folders(folder: Path) -> list:
    """``mkdir -p folder``; returns the folders it created, deepest first."""
    created, p = [], folder
    while not os.path.lexists(p) and p != p.parent:
        created.append(p)
        p = p.parent
    folder.mkdir(parents=True, exist_ok=True)
    return created


def _remove_folders(created: list) -> None:
    """Remove folders of :func:`_make_folders` again, deepest first, each only while empty (another writer may
    be using it): a failed command leaves no folder it created behind."""
    for p in created:
        try:
            p.rmdir()
        except OSError:
            return


@contextlib.contextmanager
def new_folders(folder):
    """Create ``folder`` and its missing parents for a write; on an exception remove again those it created
    (deepest first, only while empty)."""
    created = _make_folders(Path(folder))
    try:
        yield
    except BaseException:
        _remove_folders(created)
        raise


def _temp_name(path: Path) -> Path:
    return path.with_name(f"{TEMP_PREFIX}{uuid.uuid4().hex[:8]}-{path.name}")


def _fsync_path(path, directory: bool = False) -> None:
    try:
        fd = os.open(path, os.O_RDONLY | (getattr(os, "O_DIRECTORY", 0) if directory else 0))
    except OSError:
        if directory:       # some file systems do not open directories: the rename is still atomic
            return
        raise
    try:
        os.fsync(fd)
    except OSError:
        if not directory:
            raise
    finally:
        os.close(fd)


def _rename_error(exc: OSError, temp, target) -> None:
    """Make ``exc`` name ``target`` where it names the temporary ``temp`` (a file or a staging folder), or names
    nothing (a failed ``write()``: a file-size limit, a full disk; review 29b F16)."""
    temp, target = str(temp), str(target)
    if exc.filename is None:
        exc.filename = target
    for attr in ("filename", "filename2"):
        name = getattr(exc, attr, None)
        if isinstance(name, str) and name.startswith(temp):
            setattr(exc, attr, target + name[len(temp):])


def _check_not_directory(path: Path) -> None:
    if path.is_dir():
        raise DirectoryInTheWay(path)


@contextlib.contextmanager
def naming_errors(path):
    """An ``OSError`` raised inside that names no file (a failed ``write()``: ``EFBIG``, ``ENOSPC``) names ``path``:
    for writers that stream a file in several calls (review 29b F16: "[Errno 27] File too large", no file named)."""
    try:
        yield
    except OSError as exc:
        if exc.filename is None:
            exc.filename = str(path)
        raise


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path``; on success it is synced and renamed over ``path``.

    The caller writes the whole file to the yielded path.  On an exception the temporary file is
    removed and ``path`` is untouched.  Refuses (:class:`DirectoryInTheWay`) when ``path`` is a directory;
    a special file (``/dev/stdout``, a FIFO) is written directly; a symbolic link is written through (its target
    replaced, the link kept: review 22a F4 -- a command never removes a file it did not write).
    """
    path = Path(path)
    _check_not_directory(path)
    if path.exists() and not path.is_file():       # /dev/stdout, /dev/null, a FIFO: nothing to replace
        yield path                                  # (before links are resolved: /dev/stdout -> pipe:[N])
        return
    if path.is_symlink():               # written through the link (as a shell's redirection): the link stays
        path = Path(os.path.realpath(path))
        _check_not_directory(path)
    tmp = _temp_name(path)
    try:
        try:
            yield tmp
            _fsync_path(tmp)
            _check_not_directory(path)
            os.replace(tmp, path)
        except OSError as exc:
            _rename_error(exc, tmp, path)
            raise
        _fsync_path(path.parent, directory=True)
    finally:
        # only a temporary file that exists: unlinking a missing one on a read-only file system raises EROFS,
        # which would replace the error that names the target
        if os.path.lexists(tmp):
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)


@contextlib.contextmanager
def atomic_open(path, mode: str = "w", **kwargs):
    """``open`` for writing, atomically (:func:`atomic_path`): yields the file object of the
    temporary file; ``mode`` "w" or "wb" (plus ``encoding``, ``newline``, ... for text)."""
    if mode not in ("w", "wb", "wt"):
        raise ValueError(f"mode must be 'w', 'wt' or 'wb', got {mode!r}")
    with atomic_path(path) as tmp:
        fresh = Path(tmp) != Path(path)              # a temporary file; else a special file written directly
        with open(tmp, mode.replace("w", "x") if fresh else mode, **kwargs) as fh:
            yield fh


@contextlib.contextmanager
def locked_directory(folder):
    """Hold an exclusive advisory lock (``flock``) on the directory ``folder`` itself (no lock file
    is created); other writers using this lock wait.  Without ``fcntl`` it is a no-op."""
    try:
        import fcntl
    except ImportError:         # pragma: no cover - not POSIX
        yield
        return
    fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    try:
        if _key(fd) not in _HELD:               # a stage this process holds (a stage written as a folder) is ours
            with contextlib.suppress(OSError):  # a file system without flock (ENOLCK): renames stay atomic
                fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)            # releases the lock


@contextlib.contextmanager
def staged_directory(target):
    """Yield a staging directory inside the folder ``target`` (created if needed).  On success each
    file written into it replaces the file of the same name in ``target`` (one ``os.replace`` each,
    under :func:`locked_directory`); files of ``target`` not written are kept, and nothing is ever
    deleted.  On an exception the staging directory is removed, ``target`` is as it was (folders
    created for the call, ``target`` and missing parents, are removed again while empty).  A name taken
    by a directory in ``target`` raises :class:`DirectoryInTheWay` before anything is replaced."""
    target = Path(target)
    if target.name.startswith(STAGING_PREFIX) and (target / STAGE_MARKER).is_file():
        # already the (locked) stage of an outer writer, which commits its files: a second stage and lock
        # inside it would wait for the outer writer's own lock forever
        yield target
        return
    if target.exists() and not target.is_dir():
        raise NotADirectoryError(20, "exists and is not a directory", str(target))
    created = _make_folders(target)
    try:
        with locked_directory(target):   # a stage is created and locked, or swept, under the folder's lock
            _sweep_stale_stages(target)
            stage = Path(tempfile.mkdtemp(prefix=STAGING_PREFIX, dir=target))
            (stage / STAGE_MARKER).touch()
            held = _hold(stage)          # marks the stage as in use for the sweep of other writers
    except OSError as exc:               # e.g. a read-only folder: name the folder, not the temporary name
        if isinstance(exc.filename, str) and exc.filename.startswith(str(target / STAGING_PREFIX)):
            exc.filename = str(target)
        _remove_folders(created)
        raise
    try:
        try:
            yield stage
            names = sorted(n for n in os.listdir(stage) if n != STAGE_MARKER)
            for name in names:
                _fsync_path(stage / name)
            with locked_directory(target):
                for name in names:
                    _check_not_directory(target / name)
                for name in names:
                    os.replace(stage / name, target / name)
                _fsync_path(target, directory=True)
        except OSError as exc:
            _rename_error(exc, stage, target)
            raise
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        _release(held)
        _remove_folders(created)        # only when empty: another writer may be using them
        raise
    shutil.rmtree(stage, ignore_errors=True)
    _release(held)


def _hold(folder: Path):
    """An exclusive ``flock`` on ``folder`` for as long as the returned descriptor is open (None
    without ``fcntl``)."""
    try:
        import fcntl
    except ImportError:         # pragma: no cover - not POSIX
        return None
    fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    with contextlib.suppress(OSError):          # no flock here: the stage is simply not protected from a sweep
        fcntl.flock(fd, fcntl.LOCK_EX)
    with _HELD_LOCK:
        _HELD[_key(fd)] = _HELD.get(_key(fd), 0) + 1
    return fd


def _release(fd) -> None:
    if fd is not None:
        with _HELD_LOCK:
            k = _key(fd)
            _HELD[k] -= 1
            if not _HELD[k]:
                del _HELD[k]
        os.close(fd)


#: stages this process holds (:func:`_hold`), by (device, inode): :func:`locked_directory` on one of them (a
#: stage used as the target of another staged write, e.g. a model written into the stage of its folder) must
#: not flock it again -- a second flock of the same directory through another descriptor blocks forever.
_HELD: dict = {}
_HELD_LOCK = threading.Lock()


def _key(fd: int) -> tuple:
    st = os.fstat(fd)
    return st.st_dev, st.st_ino


def _sweep_stale_stages(target: Path) -> None:
    """Remove staging directories left in ``target`` by a writer that was killed (SIGKILL, power
    loss): a live writer holds a lock on its stage, a stale stage's lock is free.  Only folders holding the
    :data:`STAGE_MARKER` are stages: a user's folder with the prefix is never touched."""
    try:
        import fcntl
        names = [n for n in os.listdir(target)
                 if n.startswith(STAGING_PREFIX) and (target / n / STAGE_MARKER).is_file()]
    except (ImportError, OSError):
        return
    for name in names:
        path = target / name
        try:
            fd = os.open(path, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)        # in use by a running writer
            continue
        try:
            shutil.rmtree(path, ignore_errors=True)
        finally:
            os.close(fd)
