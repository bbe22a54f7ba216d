"""Output targets: what a command may replace, and what it must refuse.

Results are written beside their target and renamed over it (`crawlsim.io.atomic`), so whatever
the target held is gone. Before anything is computed, `check_target` refuses (`OutputError`,
exit code 2) a target that is:

* in a missing or unwritable folder, or a folder itself;
* a special file (a device such as /dev/null, a FIFO, a socket): a rename would replace the
  node itself, so these are refused even with ``--force`` (a FIFO is refused rather than
  written to: an HDF5 file cannot be streamed, and one rule for every output is clearer);
* one of the command's own input files (the gait file, a shard), even with ``--force``;
* an existing file that is not a crawlsim output of the same kind, unless ``--force``: a run
  writes over a crawlsim run results file (HDF5 with a ``format_version`` attribute), a sweep
  over a sweep file (HDF5 of kind ``sweep``, or a CSV whose header is a sweep table's), a
  figure over an image of the same format, a best gait (``optimize --write-best``) over a
  gait file crawlsim optimize wrote (its first line says so). An empty file holds nothing and
  may be replaced.

Reading what a file is costs at most a few bytes and, for HDF5, its root attributes.

A target that may be written is then claimed (`claim`) until the command ends (`release`): a
second process given the same output while the first runs is refused at once, naming the
first, where both would otherwise run and the last to finish replace the other's file. The
claim is a lock (``fcntl.flock``) on ``.NAME.lock`` beside the target, which holds the
claimant's process id and command; the system drops the lock when the process dies, so a lock
file a killed process left behind claims nothing.
"""

from __future__ import annotations

import atexit
import csv
import os
import socket
import stat
from collections.abc import Iterable
from pathlib import Path

from crawlsim.errors import OutputError

RUN, SWEEP, FIGURE, GAIT = "run", "sweep", "figure", "gait"
_WHAT = {
    RUN: "crawlsim run results file (HDF5)",
    SWEEP: "crawlsim sweep table (CSV or HDF5)",
    FIGURE: "figure",
    GAIT: "gait file written by crawlsim optimize",
}
_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
_IMAGES = {b"\x89PNG\r\n\x1a\n": "png", b"%PDF-": "pdf", b"GIF87a": "gif", b"GIF89a": "gif"}
#: The first line of a gait file crawlsim writes (`crawlsim.design.optresult`).
GAIT_HEAD = "# written by crawlsim optimize"
#: Columns every crawlsim sweep table has (CSV header), whatever else it holds.
SWEEP_COLUMNS = frozenset({"v0", "convergence", "status", "message"})


def check_target(path, kind: str, *, inputs: Iterable = (), force: bool = False, option: str = "--output") -> Path:
    """Refuse ``path`` as an output of ``kind`` (`RUN`, `SWEEP`, `FIGURE` or `GAIT`) for the reasons
    in the module docstring; return it as a Path when it may be written."""
    target = Path(path)
    source = f"{option} {path}"
    folder = Path(os.path.abspath(target)).parent
    # the folder as the system will resolve it: ``nosuchdir/../x.h5`` is x.h5 to abspath, but
    # opening it fails when nosuchdir is missing (".." follows the folder before it)
    given = Path(os.getcwd(), target).parent
    if not folder.exists() or not given.exists():
        missing = folder if not folder.exists() else _first_missing(given)
        raise OutputError(source, "", f"the folder {missing} does not exist")
    if not folder.is_dir() or not given.is_dir():
        raise OutputError(source, "", f"{folder} is not a folder")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputError(source, "", f"the folder {folder} is not writable")
    try:
        info = os.stat(target)
    except FileNotFoundError:  # nothing there (or a dangling symbolic link, which holds no data)
        for given in inputs:  # another output of the command, not written yet
            if os.path.abspath(target) == os.path.abspath(given):
                raise OutputError(
                    source,
                    "",
                    f"is the input file {given}: refusing to replace it, even with --force; choose another output name",
                ) from None
        claim(target, source)
        return target
    except OSError as error:
        raise OutputError(source, "", f"cannot inspect the target: {error.strerror}") from None
    if stat.S_ISDIR(info.st_mode):
        raise OutputError(source, "", "is a folder; give a file name such as run.h5")
    if not stat.S_ISREG(info.st_mode):
        raise OutputError(
            source,
            "",
            f"is {special_kind(info.st_mode)}, not a regular file: "
            "crawlsim never replaces special files, even with --force",
        )
    for given in inputs:
        try:
            same = os.path.samefile(target, given)
        except OSError:
            same = False
        if same:
            raise OutputError(
                source,
                "",
                f"is the input file {given}: refusing to replace it, even with --force; choose another output name",
            )
    expected = f"{FIGURE}:{_suffix(target)}" if kind == FIGURE else kind
    found = classify(target) if not force and info.st_size else expected
    if found != expected:
        raise OutputError(
            source,
            "",
            f"exists and is {_describe(found)}, not a {_WHAT[kind]}: "
            "refusing to replace it. Choose another name, remove it, "
            "or pass --force to replace it",
        )
    claim(target, source)
    return target


#: This process's claims: the absolute target -> (lock file, its open descriptor).
_CLAIMS: dict[str, tuple[str, int]] = {}


def claim(target: Path, source: str) -> None:
    """Claim ``target`` for this process until `release` (module docstring), or refuse it
    (`OutputError`) when another live process holds it."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX: no claims
        return
    key = os.path.abspath(target)
    if key in _CLAIMS:
        return
    lock = os.path.join(os.path.dirname(key), f".{os.path.basename(key)}.lock")
    while True:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = os.read(fd, 4096).decode("utf-8", errors="replace").strip() or "another process"
            os.close(fd)
            raise OutputError(
                source,
                "",
                f"is being written by another crawlsim command ({holder}): refusing to write it "
                "too. Wait for that one to finish, or choose another output name",
            ) from None
        try:
            same = os.stat(lock).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)  # its holder removed it as we opened it: claim a new one
    from crawlsim.io.provenance import command_line

    os.ftruncate(fd, 0)
    os.write(fd, f"process {os.getpid()} on {socket.gethostname()}: {command_line()}".encode())
    if not _CLAIMS:
        atexit.register(release)  # a caller other than the command line: at the latest
    _CLAIMS[key] = (lock, fd)


def release() -> None:
    """Give up every claim of this process, their lock files removed (while still locked, so
    that no other process claims a file about to go)."""
    while _CLAIMS:
        _, (lock, fd) = _CLAIMS.popitem()
        try:
            os.unlink(lock)
        except OSError:
            pass
        os.close(fd)


def _first_missing(folder: Path) -> Path:
    """The first folder of ``folder``'s path (not normalised) that does not exist."""
    part = Path(folder.anchor)
    for name in folder.parts[1:]:
        part = part / name
        if not part.exists():
            return part
    return folder


def special_kind(mode: int) -> str:
    """Words for a special file's type."""
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "a special file"


def classify(path) -> str | None:
    """What an existing regular file is: `RUN`, `SWEEP`, ``figure:<format>``, `GAIT`, or None
    (anything else, crawlsim's or not)."""
    path = Path(path)
    try:
        with open(path, "rb") as f:
            head = f.read(1 << 16)
    except OSError:
        return None
    if head.startswith(_HDF5_SIGNATURE):
        return _classify_hdf5(path)
    for signature, fmt in _IMAGES.items():
        if head.startswith(signature):
            return f"{FIGURE}:{fmt}"
    if head[4:8] == b"ftyp":  # an ISO media file (MP4), written by `crawlsim animate`
        return f"{FIGURE}:mp4"
    text = head.decode("utf-8", errors="replace")
    if "<svg" in text[:4096] and text.lstrip().startswith(("<?xml", "<svg", "<!DOCTYPE svg")):
        return f"{FIGURE}:svg"
    first_line = text.split("\n", 1)[0]
    if first_line.startswith(GAIT_HEAD):
        return GAIT
    try:
        header = next(csv.reader([first_line]))
    except (csv.Error, StopIteration):
        return None
    return SWEEP if SWEEP_COLUMNS <= set(header) else None


def _classify_hdf5(path: Path) -> str | None:
    try:
        import h5py

        with h5py.File(path, "r") as f:
            if "format_version" not in f.attrs:
                return None
            kind = f.attrs.get("kind", "")
            kind = kind.decode() if isinstance(kind, bytes) else str(kind)
    except (OSError, ValueError):
        return None
    return SWEEP if kind == "sweep" else RUN


def _suffix(path: Path) -> str:
    return path.suffix.lower().lstrip(".").replace("svgz", "svg")


def _describe(found: str | None) -> str:
    if found is None:
        return "not a crawlsim output"
    if found.startswith(FIGURE):
        return f"a {found.split(':')[1].upper()} image"
    return f"a {_WHAT[found]}"
