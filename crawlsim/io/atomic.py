"""Atomic file writes: every result file is written beside its target, then renamed over it.

A reader never sees a half-written file, and a failed write leaves nothing behind:

* the temporary file is removed when the write fails, on Ctrl-C (SIGINT raises
  KeyboardInterrupt, and the cleanup runs on the way out) and on SIGTERM (``timeout``, ``kill``,
  a batch system's time limit: a handler removes the temporary files, then does what the
  previous handler does: the command line's raises like Ctrl-C, and without one the signal's
  default action ends the process, so its status is still "killed by SIGTERM"). The command
  line raises both where it is safe to (`crawlsim.interrupts`), and `publish` never renames a
  file whose command was interrupted;
* a process killed outright (SIGKILL, a power cut) cannot clean up, so temporary files carry
  the host and process id that wrote them, ``.NAME.HOST.PID.XXXX.tmp``, and the next write of
  the same target removes those whose process is gone (on this host: a process id means
  nothing elsewhere on a shared file system);
* the rename never replaces a special file (a device such as /dev/null, a FIFO, a socket): the
  target is checked again just before it (`crawlsim.io.outputs` refuses them up front).

Folder problems (missing, read-only) are `OutputError` naming the folder, and so is a full disk
(or quota, or an I/O error) while writing: ``no space left on device: PATH``, the temporary file
removed, exit code 2. HDF5 files are written through `GuardedFile`: libhdf5, after a failed
write, keeps failing on every flush and close and can crash the interpreter on the way out; the
guard records the first failure, raises it, and drops every later write (the file is discarded
anyway), so the file closes cleanly.
"""

from __future__ import annotations

import errno
import io
import os
import re
import signal
import socket
import stat
import tempfile
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from crawlsim import interrupts
from crawlsim.errors import OutputError
from crawlsim.io.outputs import special_kind

_HOST = re.sub(r"[^A-Za-z0-9_-]", "_", socket.gethostname()) or "host"
_LIVE: set[Path] = set()  # temporary files of this process not yet published or removed
_PREVIOUS_HANDLER: object = None
_LOCK = threading.Lock()


def _stale_pattern(target: Path) -> re.Pattern:
    return re.compile(re.escape(f".{target.name}.") + r"(?P<host>[A-Za-z0-9_-]+)\.(?P<pid>\d+)\.[^.]+\.tmp")


def remove_stale(target: Path) -> list[Path]:
    """Remove the temporary files of ``target`` left by dead processes of this host; return them."""
    target = Path(target)
    folder = Path(os.path.abspath(target)).parent
    pattern = _stale_pattern(target)
    removed: list[Path] = []
    try:
        names = os.listdir(folder)
    except OSError:
        return removed
    for name in names:
        match = pattern.fullmatch(name)
        if match is None or match["host"] != _HOST or _alive(int(match["pid"])):
            continue
        try:
            (folder / name).unlink()
            removed.append(folder / name)
        except OSError:
            pass
    return removed


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # another user's live process
    except OverflowError:
        return False
    return True


def temporary_beside(target: Path) -> Path:
    """An empty temporary file in ``target``'s folder (same file system, so rename is atomic),
    registered for removal on SIGTERM; stale ones of dead processes are removed first."""
    target = Path(target)
    folder = Path(os.path.abspath(target)).parent
    remove_stale(target)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.{_HOST}.{os.getpid()}.", suffix=".tmp", dir=folder)
    except FileNotFoundError:
        raise OutputError(str(target), "", f"the folder {folder} does not exist") from None
    except OSError as error:
        raise OutputError(str(target), "", f"cannot write in the folder {folder}: {error.strerror}") from None
    os.close(fd)
    path = Path(tmp)
    _register(path)
    return path


def discard(tmp: Path) -> None:
    """Remove a temporary file (if it is still there) and forget it."""
    try:
        Path(tmp).unlink(missing_ok=True)
    finally:
        _forget(Path(tmp))


def publish(tmp: Path, target: Path) -> None:
    """Give a finished temporary file the usual permissions (mkstemp makes it 0600) and rename
    it over ``target`` atomically, unless ``target`` has become a special file meanwhile, or the
    command has been interrupted (`crawlsim.interrupts`: a file it was told to abandon is not
    published)."""
    interrupts.check()
    target = Path(target)
    try:
        mode = os.stat(target).st_mode
    except FileNotFoundError:
        mode = None
    if mode is not None and not stat.S_ISREG(mode):
        raise OutputError(
            str(target), "", f"is {special_kind(mode)}, not a regular file: crawlsim never replaces special files"
        )
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    os.replace(tmp, target)
    interrupts.settle()
    _forget(Path(tmp))


#: Errors of a write that say the disk (not the request) is at fault.
DISK_ERRORS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO})


def disk_error(target, error: OSError, outcome: str = "not written") -> OutputError:
    """``no space left on device: PATH`` (or the disk's other complaint) as an `OutputError`."""
    reason = error.strerror or os.strerror(error.errno or errno.EIO)
    return OutputError("", "", f"{reason[:1].lower()}{reason[1:]}: {target} ({outcome})")


@contextmanager
def atomic_path(target) -> Iterator[Path]:
    """Yield a temporary path to write; on success it replaces ``target``, on error (or
    KeyboardInterrupt, or SIGTERM) it is removed. A full disk is `disk_error`."""
    tmp = temporary_beside(Path(target))
    try:
        try:
            yield tmp
            publish(tmp, Path(target))
        except OSError as error:
            if error.errno in DISK_ERRORS:
                raise disk_error(target, error) from None
            raise
    finally:
        discard(tmp)


class GuardedFile(io.FileIO):
    """A file for libhdf5 (h5py's file-object driver) that never reports a failed write to it:
    the first failure (a full disk) is recorded in `error`, and it and every later write,
    truncation or flush are dropped (the file will be discarded). libhdf5 told of a failed write
    keeps failing on every flush and close, prints errors from finalizers, and can crash the
    interpreter on the way out; the writer checks `error` instead (`check`) and stops."""

    error: OSError | None = None

    def write(self, data) -> int:
        if self.error is None:
            try:
                return self._write(data)
            except OSError as error:
                self.error = error
        return len(memoryview(data))

    def _write(self, data) -> int:
        return super().write(data)

    def truncate(self, size=None) -> int:
        if self.error is None:
            try:
                return super().truncate(size)
            except OSError as error:
                self.error = error
        return 0 if size is None else size

    def flush(self) -> None:
        if self.error is None:
            super().flush()

    def check(self) -> None:
        """Raise the recorded failure, if any."""
        if self.error is not None:
            raise self.error


@contextmanager
def guarded(tmp: Path) -> Iterator[GuardedFile]:
    """`GuardedFile` open on ``tmp``; its recorded failure is raised (as itself, the OSError)
    whatever the writer raised on top of it, or if the writer swallowed it."""
    raw = GuardedFile(tmp, "w+")
    try:
        yield raw
    except BaseException:
        if raw.error is not None:
            raise raw.error from None
        raise
    finally:
        raw.close()
    if raw.error is not None:
        raise raw.error


def _register(path: Path) -> None:
    global _PREVIOUS_HANDLER
    with _LOCK:
        if not _LIVE and threading.current_thread() is threading.main_thread():
            try:
                _PREVIOUS_HANDLER = signal.signal(signal.SIGTERM, _on_sigterm)
            except ValueError:  # pragma: no cover - not the main interpreter
                _PREVIOUS_HANDLER = None
        _LIVE.add(path)


def _forget(path: Path) -> None:
    global _PREVIOUS_HANDLER
    with _LOCK:
        _LIVE.discard(path)
        if not _LIVE and _PREVIOUS_HANDLER is not None and threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGTERM, _PREVIOUS_HANDLER)  # type: ignore[arg-type]
            _PREVIOUS_HANDLER = None


def _on_sigterm(signum, frame):
    """Remove every temporary file, then do what the previous handler would have done."""
    for path in list(_LIVE):
        try:
            path.unlink(missing_ok=True)
        except OSError:
            pass
    previous = _PREVIOUS_HANDLER
    if callable(previous):
        previous(signum, frame)
    elif previous != signal.SIG_IGN:
        # Die of the signal as if no handler were installed: an exception raised here could
        # land in a finalizer and be swallowed, and the finished-file path must not run.
        signal.signal(signum, signal.SIG_DFL)
        os.kill(os.getpid(), signum)
