"""Writers (and a reader) for the output contract, ``docs/output-format.md``.

The only modules that import h5py (:mod:`.hdf5`) and rerun (:mod:`.rrd`); import them
explicitly, so that writing one format never pays for importing the other.

Every file is written to a temporary name beside its final one and renamed into place only when
complete (:func:`atomic_path`): a temporary says whose it is (``.<name>.<pid>.<random>.tmp``),
is removed on every exit path a process survives (errors, Ctrl-C, SIGTERM), and one left by a
killed process is removed by the next write into that folder. :func:`output_lock` keeps two
runs from interleaving one scene's ``.h5`` and ``.rrd``.
"""
from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import pathlib
import re
import shutil
import threading
import time
import uuid
from collections.abc import Iterator

from ..errors import LinkpipeError

#: what a write needs beyond its arrays' bytes (metadata, chunk indexes), and at least this much
SPACE_MARGIN, SPACE_MINIMUM = 1.1, 1 << 20
_TEMP = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)\.[0-9a-f]{12}\.tmp$")
#: temporaries of earlier versions carry no process id: removed once they are this old (s)
_UNOWNED = re.compile(r"^\.(?P<name>.+)\.[0-9a-f]{12}\.tmp$")
UNOWNED_AGE_S = 3600
_INTERRUPTED = False


class OutputError(LinkpipeError, OSError):
    """An output could not be written (no space, no permission): nothing was left under the
    final name, the previous file (if any) is intact. The run goes on with the next scene."""

    exit_code = 1

    def __str__(self) -> str:
        return self.strerror or super().__str__()


def interrupt(interrupted: bool = True) -> None:
    """Mark the process as interrupted: no temporary is renamed into place from now on (an
    interrupt that a library swallowed while writing must not publish a half-meant file).
    ``interrupt(False)`` clears the mark (a new command in the same process)."""
    global _INTERRUPTED
    _INTERRUPTED = interrupted


def stop_if_interrupted() -> None:
    """Raise KeyboardInterrupt where a signal was marked (:func:`interrupt`) but its exception
    was swallowed (it landed in a finaliser): a long run checks between its segments."""
    if _INTERRUPTED:
        raise KeyboardInterrupt


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_temporaries(folder: str | os.PathLike) -> list[pathlib.Path]:
    """Remove the temporaries of processes that no longer run; return what was removed."""
    removed = []
    now = time.time()
    for path in pathlib.Path(folder).glob(".*.tmp"):
        m = _TEMP.match(path.name)
        dead = m and int(m.group("pid")) != os.getpid() and not _alive(int(m.group("pid")))
        unowned = not m and _UNOWNED.match(path.name)
        try:
            old = unowned and now - path.stat().st_mtime > UNOWNED_AGE_S
        except OSError:
            continue
        if dead or old:
            path.unlink(missing_ok=True)
            removed.append(path)
    return removed


def check_space(path: str | os.PathLike, n_bytes: int) -> None:
    """OutputError before a write of about ``n_bytes`` that the folder's free space cannot hold."""
    folder = pathlib.Path(path).parent
    need = max(int(n_bytes * SPACE_MARGIN), SPACE_MINIMUM)
    free = shutil.disk_usage(folder).free
    if need > free:
        raise OutputError(errno.ENOSPC, f"{path}: not written: it needs about {need / 2**20:.1f} MiB "
                          f"and {free / 2**20:.1f} MiB are free in {folder}; free space or use "
                          "--out on another disk")


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, n_bytes: int = 0) -> Iterator[pathlib.Path]:
    """Yield a temporary path beside ``path``; rename it into place only if the block succeeds
    (and the process was not interrupted). ``n_bytes``: the write's estimated size, checked
    against the free space first.

    On any exception the temporary file is removed and ``path`` keeps its previous content; a
    full disk (ENOSPC, EDQUOT) during the write becomes an :class:`OutputError` naming the file.
    """
    path = pathlib.Path(path)
    remove_stale_temporaries(path.parent)
    check_space(path, n_bytes)
    _forget_cached(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:12]}.tmp")
    try:
        yield tmp
        if _INTERRUPTED:
            raise KeyboardInterrupt
        _fsync(tmp)  # the data on disk before the name points at it (a crash keeps old or new)
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        if getattr(exc, "errno", None) in (errno.ENOSPC, errno.EDQUOT) or "No space" in str(exc):
            raise OutputError(errno.ENOSPC, f"{path}: not written: the disk is full "
                              f"({shutil.disk_usage(path.parent).free / 2**20:.1f} MiB free); "
                              "free space or use --out on another disk") from None
        raise
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _forget_cached(path: pathlib.Path) -> None:
    """Drop ``path``'s pages from the page cache on a helper thread, if it exists: the file
    stays as it is on disk (a run that fails keeps it), but its replacement no longer frees
    them while the run waits (measured: a 134 MB file's rename into place 26 -> 15 ms)."""
    if not hasattr(os, "posix_fadvise") or not path.exists():
        return

    def forget():
        try:
            fd = os.open(path, os.O_RDONLY)
        except OSError:
            return
        try:
            os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED)
        except OSError:
            pass
        finally:
            os.close(fd)

    threading.Thread(target=forget, name="linkpipe-forget", daemon=True).start()


def _fsync(path: pathlib.Path) -> None:
    """fsync ``path`` in a helper thread while this one waits in short sleeps: a long sweep's
    file may take seconds to reach the disk, and a signal (Ctrl-C) must still stop the run at
    once (Python runs signal handlers only between the main thread's own steps)."""
    if not path.exists():
        return
    fd = os.open(path, os.O_RDONLY)
    failed: list[BaseException] = []

    def sync():
        try:
            os.fsync(fd)
        except OSError as exc:
            failed.append(exc)
        finally:
            os.close(fd)  # here: an interrupted wait does not leave it open

    worker = threading.Thread(target=sync, name="linkpipe-fsync", daemon=True)
    worker.start()
    while worker.is_alive():
        worker.join(0.05)
    if failed:
        raise failed[0]


def output_folder(out: str | os.PathLike) -> pathlib.Path:
    """``out`` made (with its parents) as the folder outputs go to. A file there or on the
    way is a wrong argument (one message naming that file, exit 2, as an ``--out`` that is a
    file); a folder the machine will not make (no permission, a read-only or full disk) is an
    output not written (:class:`OutputError`, one line, exit 1: docs/faults.md)."""
    out = pathlib.Path(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        blocking = next((p for p in (out, *out.parents) if p.exists() and not p.is_dir()), out)
        raise LinkpipeError(f"--out {out}: cannot be the output folder: {blocking} is a file, "
                            "not a folder — give --out a folder (made if missing)") from None
    except OSError as exc:  # no permission, a read-only or full disk: the machine's (exit 1)
        raise OutputError(exc.errno, f"--out {out}: cannot be made: {exc.strerror or exc} — "
                          "give --out a folder you may write to") from None
    return out


@contextlib.contextmanager
def output_lock(folder: str | os.PathLike, name: str) -> Iterator[None]:
    """Hold an advisory lock on one output name in ``folder`` (``.<name>.lock``, flock) while its
    files are written: a second run writing the same name waits, so an ``.h5`` and its ``.rrd``
    always come from the same run. The lock file is removed when its holder is done (no empty
    ``.<name>.lock`` stays behind): removed while still held, so a run that waited on it finds
    its name gone once it holds it, and locks the name afresh."""
    lock = pathlib.Path(folder) / f".{name}.lock"
    while True:
        handle = open(lock, "a")
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            held = os.fstat(handle.fileno())
            now = os.stat(lock)
            if (held.st_dev, held.st_ino) == (now.st_dev, now.st_ino):
                break  # the file we hold is the one the name points at
        except FileNotFoundError:
            pass  # its holder removed it while we waited: lock the name afresh
        handle.close()
    try:
        yield
    finally:
        lock.unlink(missing_ok=True)
        fcntl.flock(handle, fcntl.LOCK_UN)
        handle.close()


#: what the longest file a run writes adds to its output name: the temporary of a study's
#: recording, ``.<name>_study.rrd.<pid>.<12 hex digits>.tmp`` (a pid of up to 10 digits)
NAME_OVERHEAD = len("._study.rrd..") + 10 + 12 + len(".tmp")


def longest_output_name(folder: str | os.PathLike) -> tuple[int, int]:
    """``(longest name, limit)``: the most bytes (UTF-8) an output name may have in ``folder``
    (made or not yet) so that every file named after it, its lock and its temporaries fit the
    file system's limit on one file name (``limit``, bytes: 255 where it does not say)."""
    where = pathlib.Path(folder).absolute()
    while not where.exists() and where != where.parent:
        where = where.parent
    try:
        limit = int(os.pathconf(where, "PC_NAME_MAX"))
    except (OSError, ValueError):
        limit = 255
    return limit - NAME_OVERHEAD, limit
