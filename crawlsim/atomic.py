"""Atomic file writes: every result file is written beside its target, then renamed over it.

A reader never sees a half-written file, and a failed write leaves nothing behind.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


def temporary_beside(target: Path) -> Path:
    """An empty temporary file in ``target``'s folder (same file system, so rename is atomic)."""
    target = Path(target)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp",
                               dir=target.resolve().parent)
    os.close(fd)
    return Path(tmp)


def publish(tmp: Path, target: Path) -> None:
    """Give a finished temporary file the usual permissions (mkstemp makes it 0600) and rename
    it over ``target`` atomically."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    os.replace(tmp, target)


@contextmanager
def atomic_path(target) -> Iterator[Path]:
    """Yield a temporary path to write; on success it replaces ``target``, on error it is
    removed."""
    tmp = temporary_beside(Path(target))
    try:
        yield tmp
        publish(tmp, Path(target))
    finally:
        tmp.unlink(missing_ok=True)
