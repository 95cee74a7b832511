"""One run per output folder (design §10): claim a folder, lock it, clear an old run with ``--overwrite``.

A folder is refused when it holds another run's files, unless ``overwrite`` is asked, which
first removes exactly those files (the names in :data:`RUN_FILES`, the folders of :data:`RUN_DIRS`
holding only their files, our own stale temporary files; the registered outputs' among them,
design §22). A folder that holds anything else (the user's files) is
refused in both cases: nothing we did not write is ever deleted.

Concurrent writers are refused with an ``fcntl.flock`` on ``DIR/.bioform.lock``: the kernel
drops the lock when its holder dies, so a killed run leaves no stale lock (at most the empty
lock file, which the next run reuses). The lock file is removed when the run ends.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
from collections.abc import Iterator
from pathlib import Path

from bioform_mj.core.errors import InputError
from bioform_mj.outputs.files import check_out_dir
from bioform_mj.outputs.registry import output_dirs, output_files
from bioform_mj.outputs.scenexml import ASSET_SUFFIXES, ASSETS_DIR

#: Files a run or a table1 writes into its folder: its record, and those of the registered outputs
#: (:mod:`~bioform_mj.outputs.registry`: video.mp4, run.rrd, ...)
RUN_FILES = (
    frozenset({"summary.json", "resolved.toml", "log.npz", "scene.xml", "MUJOCO_LOG.TXT", "table1.json", "table1.md"})
    | output_files()
)
#: Files ``bioform calibrate`` writes into its folder (another kind of run: design §16).
CALIBRATION_FILES = frozenset(
    {"calibration.json", "calibration.md", "calibration.partial.json", "evaluations.jsonl", "MUJOCO_LOG.TXT"}
)
#: Every file name one of our commands writes as its run's record.
KNOWN_FILES = RUN_FILES | CALIBRATION_FILES
#: Folders a run writes, and the file suffixes they may hold (``assets/``: the files ``scene.xml``
#: names, copied beside it, design §12; the registered outputs', e.g. ``figures/``).
RUN_DIRS = {**output_dirs(), ASSETS_DIR: ASSET_SUFFIXES}
LOCK_NAME = ".bioform.lock"
#: the temporary names of :func:`~bioform_mj.outputs.files.atomic_path` (``.NAME.XXXXXXXX.tmp``)
_TMP = re.compile(r"^\.(?P<name>.+)\.[A-Za-z0-9_]+\.tmp$")


class FolderBusy(InputError):
    """Another process holds the folder's lock (exit 2)."""


def take_lock(path: Path, what: str = "output directory", doing: str = "writing a run there") -> int:
    """Lock the existing folder ``path`` (``flock`` on ``path/.bioform.lock``, our pid written in it);
    returns the locked file descriptor, or raises :class:`FolderBusy` naming the holder's pid."""
    import fcntl

    lock = Path(path) / LOCK_NAME
    while True:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            try:
                pid = os.read(fd, 32).decode(errors="replace").strip()
            finally:
                os.close(fd)
            who = f"process {pid}" if pid.isdigit() else "another process"
            raise FolderBusy(f"{what} '{path}' is in use: {who} is {doing}") from None
        try:  # the holder we waited on may have removed the file: then lock the new one
            same = os.fstat(fd).st_ino == os.stat(lock).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    try:  # who holds it, for the message of a refused second run
        os.ftruncate(fd, 0)
        os.write(fd, str(os.getpid()).encode())
    except OSError as exc:  # disk full, ulimit -f (design §17): the run could write nothing either
        from bioform_mj.core.errors import WriteFailed

        os.close(fd)
        raise WriteFailed(str(lock), exc) from exc
    return fd


def release_lock(path: Path, fd: int) -> None:
    """Undo :func:`take_lock`: remove the lock file (before unlocking: a waiter sees the inode change)."""
    with contextlib.suppress(FileNotFoundError):
        os.unlink(Path(path) / LOCK_NAME)
    os.close(fd)


@contextlib.contextmanager
def folder_lock(path: Path, what: str = "output directory", doing: str = "writing a run there") -> Iterator[None]:
    """Hold the folder's lock (:func:`take_lock`) while the block runs."""
    fd = take_lock(path, what, doing)
    try:
        yield
    finally:
        release_lock(path, fd)


def is_ours_transient(name: str) -> bool:
    """Whether the folder entry ``name`` is one of ours that comes and goes: the lock, a writability probe, or a
    temporary ``.NAME.XXXX.tmp`` of :func:`~bioform_mj.outputs.files.atomic_path`."""
    return name == LOCK_NAME or name.startswith(".bioform-probe-") or bool(_TMP.match(name))


def _is_tmp(name: str, allowed: frozenset[str] | tuple[str, ...]) -> bool:
    m = _TMP.match(name)
    if not m:
        return False
    inner = m.group("name")
    return inner in allowed if isinstance(allowed, frozenset) else inner.endswith(allowed)


def _stale_dir(name: str, files: frozenset[str]) -> bool:
    """A run folder's temporary (``.rosbag.XXXX.tmp``, outputs/rosbag.py: renamed when complete)."""
    m = _TMP.match(name)
    return bool(m) and files is RUN_FILES and m.group("name") in RUN_DIRS


def survey(path: Path, files: frozenset[str] = RUN_FILES) -> tuple[list[str], list[str]]:
    """``(run files, foreign entries)`` in ``path`` (names; folders end with ``/``); ``files``: the
    names a run of this kind writes (:data:`RUN_FILES`, :data:`CALIBRATION_FILES`)."""
    ours: list[str] = []
    foreign: list[str] = []
    if not path.is_dir():
        return ours, foreign
    for entry in sorted(os.scandir(path), key=lambda e: e.name):
        name = entry.name
        if name == LOCK_NAME or name.startswith(".bioform-probe-"):  # ours: the lock, a writability probe
            continue
        if name in files or _is_tmp(name, files):
            (ours if entry.is_file(follow_symlinks=False) else foreign).append(name)
        elif _stale_dir(name, files) and entry.is_dir(follow_symlinks=False):  # a bag folder being written
            ours.append(name + "/")
        elif name in RUN_DIRS and files is RUN_FILES and entry.is_dir(follow_symlinks=False):
            sfx = RUN_DIRS[name]
            inner = [e for e in os.scandir(entry.path)]
            if all(e.is_file(follow_symlinks=False) and (e.name.endswith(sfx) or _is_tmp(e.name, sfx)) for e in inner):
                ours.append(name + "/")
            else:
                bad = next(
                    e.name
                    for e in inner
                    if not (e.is_file(follow_symlinks=False) and (e.name.endswith(sfx) or _is_tmp(e.name, sfx)))
                )
                foreign.append(f"{name}/{bad}")
        else:
            foreign.append(name + ("/" if entry.is_dir(follow_symlinks=False) else ""))
    return ours, foreign


def _short(names: list[str], k: int = 4) -> str:
    return ", ".join(names[:k]) + (f" and {len(names) - k} more" if len(names) > k else "")


class RunDir:
    """The output folder of one run: :meth:`check` before any work, then ``with`` it while writing.

    ``with RunDir(...)`` creates the folder, takes the lock (or raises :class:`FolderBusy`),
    checks the contents again under the lock and, with ``overwrite``, removes the old run's
    files. On leaving, the lock is released and its file removed; a folder this object created
    and nothing was written to is removed again.
    """

    def __init__(
        self,
        path: str | Path,
        overwrite: bool = False,
        what: str = "output directory",
        files: frozenset[str] = RUN_FILES,
        resumable: frozenset[str] = frozenset(),
    ) -> None:
        """``files``: what this kind of run writes; ``resumable``: those of its files that an unfinished
        run leaves and the same command resumes from (a folder holding only them is accepted)."""
        self.path = Path(path)
        self.overwrite = overwrite
        self.what = what
        self.files = files
        self.resumable = resumable
        self._fd: int | None = None
        self._created: list[Path] = []

    # -- before any work ---------------------------------------------------------------
    def check(self) -> RunDir:
        """Raise :class:`InputError` if the folder cannot be written or holds what we must not touch."""
        check_out_dir(self.path, self.what)
        self._check_contents()
        return self

    def _check_contents(self) -> None:
        ours, foreign = survey(self.path, self.files)
        real = [n for n in ours if not _TMP.match(n.rstrip("/"))]
        other = [n for n in foreign if n in KNOWN_FILES or n.rstrip("/") in RUN_DIRS]
        if other:
            raise InputError(
                f"{self.what} '{self.path}' holds another kind of run ({_short(other)}); "
                f"choose an empty or new folder (nothing there is deleted, even with --overwrite)"
            )
        if real and all(n in self.resumable for n in real) and not self.overwrite:
            return  # an unfinished run of this kind: the same command resumes it
        if foreign:
            raise InputError(
                f"{self.what} '{self.path}' holds files that are not a run's ({_short(foreign)}); "
                f"choose an empty or new folder (nothing there is deleted, even with --overwrite)"
            )
        if real and not self.overwrite:
            raise InputError(
                f"{self.what} '{self.path}' holds another run's files ({_short(real)}); "
                f"use --overwrite to replace them, or choose another --out"
            )

    # -- while writing -----------------------------------------------------------------
    def __enter__(self) -> RunDir:
        missing = []
        p = self.path
        while not p.exists() and p.parent != p:
            missing.append(p)
            p = p.parent
        self.path.mkdir(parents=True, exist_ok=True)
        self._created = missing  # deepest first
        try:
            self._lock()
            self._check_contents()  # again, under the lock: another run may have written meanwhile
            self._clear()
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def _lock(self) -> None:
        self._fd = take_lock(self.path, self.what)

    def _clear(self) -> None:
        """Remove stale temporaries always, and the old run's files with ``overwrite``."""
        ours, _ = survey(self.path, self.files)
        for name in ours:
            target = self.path / name.rstrip("/")
            if not (self.overwrite or _TMP.match(name.rstrip("/"))):
                continue
            if name.endswith("/"):
                shutil.rmtree(target)
            else:
                with contextlib.suppress(FileNotFoundError):
                    target.unlink()

    def __exit__(self, *exc) -> None:
        if self._fd is not None:
            release_lock(self.path, self._fd)
            self._fd = None
        for d in self._created:  # nothing written: leave no folder behind
            try:
                d.rmdir()
            except OSError:
                break

    @property
    def written(self) -> bool:
        """True when the folder holds any file of a run."""
        return bool(survey(self.path, self.files)[0])


#: what a sweep writes into its folder (design §16), beside the lock and the temporary ``.NAME.XXXX.tmp`` names
SWEEP_ENTRIES = frozenset(
    {"runs", "bags", "sweep.json", "runs.csv", "runs.parquet", "stats.json", "stats.md", "MUJOCO_LOG.TXT"}
)


def check_sweep_dir(out: Path) -> None:
    """InputError (exit 2) when ``out`` holds another kind of run (a run's ``summary.json``, a calibration)
    or anything a sweep does not write (:data:`SWEEP_ENTRIES`): a sweep folder holds a sweep (design §16).
    ``--out`` a symlink to ``/`` wrote the sweep's tables into the root folder (issue 28), and its ``bags`` a
    symlink to ``/`` the sweep's bags: a sweep's own entries must not be symlinks (``runs``, ``bags``: folders)."""
    if out.is_dir():
        names = sorted(os.listdir(out))
        other = [n for n in names if n in KNOWN_FILES]
        if other:
            raise InputError(
                f"sweep directory '{out}' holds another kind of run ({', '.join(other[:4])}); choose an empty, "
                "new or sweep folder"
            )
        foreign = [n for n in names if n not in SWEEP_ENTRIES and not is_ours_transient(n)]
        if foreign:
            shown = ", ".join(foreign[:4]) + (f" and {len(foreign) - 4} more" if len(foreign) > 4 else "")
            raise InputError(
                f"sweep directory '{out}' holds files that are not a sweep's ({shown}); choose an empty, new or "
                "sweep folder (nothing there is deleted)"
            )
        for n in sorted(set(names) & SWEEP_ENTRIES):  # bags -> / wrote a sweep's bag into the root folder (trust5)
            p = out / n
            if p.is_symlink() or (n in ("runs", "bags") and not p.is_dir()):
                what = f"a symlink (to '{os.readlink(p)}')" if p.is_symlink() else "not a folder"
                raise InputError(
                    f"sweep directory '{out}': its '{n}' is {what}; a sweep writes only into its own folders "
                    "(choose an empty or new folder; nothing there is deleted)"
                )
