"""Ctrl-C (SIGINT) and SIGTERM in the command-line program: where the exception is raised.

Python raises KeyboardInterrupt at whatever bytecode runs when the signal arrives. Inside another
library's code that can go wrong in ways no clean-up can repair: a ctypes callback (numba loading
the compiled kernel from its cache) or a libhdf5 write callback reports the exception as
"ignored" and carries on, so the command runs to its end and publishes a file it was told to
abandon; an object interrupted half-built prints a traceback from its finalizer. So the command
line's handlers (`installed`) raise at once only where crawlsim's own code is running, and
otherwise note the signal (`pending`): it is raised at the next safe point (`check`: after every
period of a run or of a batched sweep point, every step of the limit search and frame of an
animation, in the waits for local or Dask workers, and before a finished file is renamed into
place) or, at the latest, when the command returns (an exit code or an error it ends with gives
way to the signal's). A second signal while one is pending is raised at once wherever the
program is (the way out of a long first compilation), but for a write libhdf5 calls back.
Once a file is in place (`settle`, after each rename), a signal is only noted: raised at the
next safe point if more work follows, and ignored when the command then ends, whose results
are written and whose exit code stands.

Without `installed` (the Python API) nothing changes: Python's own handlers stay, and `check` is
a no-op.
"""

from __future__ import annotations

import os
import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType


class Terminated(KeyboardInterrupt):
    """SIGTERM (a batch system ending a job), raised like Ctrl-C so that the same clean-up runs:
    temporary files removed, a sweep's journal flushed."""


#: The signal noted but not yet raised (`pending`).
_PENDING: int | None = None
#: Whether a file of the command is in place (`settle`).
_SETTLED = False

_PACKAGE = os.path.dirname(os.path.abspath(__file__)) + os.sep
#: crawlsim's code that other libraries call back (h5py's file driver writes through
#: `crawlsim.io.atomic.GuardedFile`): an exception raised there is theirs to swallow.
_CALLED_BACK = frozenset({os.path.join(_PACKAGE, "io", "atomic.py")})


def pending() -> int | None:
    """The signal number noted and not yet raised, or None."""
    return _PENDING


def exception_for(signum: int) -> KeyboardInterrupt:
    return Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()


def _called_back(frame: FrameType | None) -> bool:
    """Whether ``frame`` runs inside a write libhdf5 called back (a `_CALLED_BACK` frame on
    its stack)."""
    while frame is not None:
        if frame.f_code.co_filename in _CALLED_BACK:
            return True
        frame = frame.f_back
    return False


def _handler(signum: int, frame: FrameType | None) -> None:
    """Raise now in crawlsim's own code; note the signal elsewhere, or raise a second one now,
    but never inside a write that libhdf5 calls back (the write returns at once, and an
    exception there is swallowed and leaves libhdf5 broken): a noted signal waits for `check`.
    A second signal raised in another library's code stays noted as well, in case that
    library swallows it too."""
    global _PENDING
    if _called_back(frame) or _SETTLED:
        _PENDING = signum
        return
    ours = frame is not None and frame.f_code.co_filename.startswith(_PACKAGE)
    if not ours and _PENDING is None:
        _PENDING = signum
        return
    _PENDING = None if ours else signum
    raise exception_for(signum)


def settle() -> None:
    """A file of the command is in place: a signal from now on waits for `check`, and is
    ignored if the command ends without one."""
    global _SETTLED
    _SETTLED = True


def check() -> None:
    """Raise the pending signal's exception, if one is noted (in the main thread only)."""
    global _PENDING
    signum = _PENDING
    if signum is not None and threading.current_thread() is threading.main_thread():
        _PENDING = None
        raise exception_for(signum)


@contextmanager
def installed() -> Iterator[None]:
    """The handlers above for SIGINT and SIGTERM while the block runs (the main thread only;
    elsewhere nothing changes), the previous ones restored after it; a signal still pending when
    the block ends is raised then."""
    global _PENDING, _SETTLED
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _PENDING, _SETTLED = None, False
    previous = {signum: signal.signal(signum, _handler) for signum in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
        if not _SETTLED:
            check()
    except KeyboardInterrupt:
        raise
    except BaseException as exc:
        # the command ended otherwise (an error, an exit code) after a signal it was given:
        # the signal's exit wins, unless it came after the results were in place
        if _PENDING is not None and not _SETTLED:
            raise exception_for(_PENDING) from exc
        raise
    finally:
        for signum, handler in previous.items():
            if handler is not None:  # None: a handler not installed from Python
                signal.signal(signum, handler)
        _PENDING, _SETTLED = None, False
