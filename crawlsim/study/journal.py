"""The journal of a sweep: finished points as JSON lines next to the output (``OUT.journal``),
so that an interrupted sweep resumes without recomputing them."""

from __future__ import annotations

import io
import json
import os
import stat
import time
from collections.abc import Callable
from pathlib import Path

from crawlsim.errors import GaitError, OutputError
from crawlsim.io.atomic import DISK_ERRORS, disk_error
from crawlsim.io.outputs import special_kind
from crawlsim.study.points import PointResult

#: Seconds between two flushes of the journal (and at the end, and on an interrupt).
JOURNAL_SECONDS = 3.0


class Journal:
    """JSON lines next to the output: a header, then one line per finished point.

    The first rows are written at once (the journal shows up with the first finished points);
    later rows are buffered and written, flushed and fsynced every ``interval`` seconds, on
    `flush` and on `close` (which the sweep calls at the end and on an interrupt), so an
    interrupted sweep keeps every finished point and a killed one loses at most the last
    ``interval`` seconds. A torn last line (a kill mid-write) is ignored on reading.
    """

    def __init__(
        self,
        path: Path,
        fingerprint: str,
        *,
        interval: float | None = None,
        clock: Callable[[], float] = time.monotonic,
    ):
        self.path = Path(path)
        self.fingerprint = fingerprint
        self.interval = JOURNAL_SECONDS if interval is None else float(interval)
        self.clock = clock
        self._file: io.TextIOWrapper | None = None
        self._buffer: list[PointResult] = []
        self._last: float | None = None  # time of the last flush

    def _check_regular(self) -> None:
        """Refuse a journal path that is not a regular file (a FIFO would block the sweep
        forever, a device swallow its points): `OutputError`, exit code 2."""
        try:
            mode = os.stat(self.path).st_mode
        except FileNotFoundError:
            return
        except OSError as error:
            raise OutputError(str(self.path), "", f"cannot inspect the journal: {error.strerror}") from None
        if not stat.S_ISREG(mode):
            raise OutputError(
                str(self.path),
                "",
                f"is {special_kind(mode)}, not a regular file: "
                "the journal of a sweep must be a regular file; "
                "remove it, or choose another output name",
            )

    def load(self) -> dict[int, PointResult]:
        """Finished points of an earlier run of the same sweep ({} when there is none)."""
        self._check_regular()
        if not self.path.exists():
            return {}
        done = {}
        with open(self.path, encoding="utf-8") as f:
            lines = f.read().split("\n")
        try:
            header = json.loads(lines[0])
        except (json.JSONDecodeError, IndexError):
            header = {}
        if not isinstance(header, dict) or header.get("fingerprint") != self.fingerprint:
            raise GaitError(
                str(self.path),
                "",
                "this journal belongs to a different sweep (other "
                "gait, paths, values or shard); delete it to start "
                "afresh, or rerun the sweep that wrote it",
            )
        for line in lines[1:]:
            try:
                row = PointResult.from_json(json.loads(line))
            except (json.JSONDecodeError, TypeError, ValueError):
                continue
            done[row.index] = row
        return done

    def append(self, results) -> None:
        self._buffer.extend(results)
        if self._last is None or self.clock() - self._last >= self.interval:
            self.flush()

    def flush(self) -> None:
        """Write the buffered rows, flush and fsync."""
        if not self._buffer:
            return
        self._last = self.clock()
        rows, self._buffer = self._buffer, []
        try:
            if self._file is None:
                self._check_regular()
                new = not self.path.exists() or self.path.stat().st_size == 0
                self._file = open(self.path, "a", encoding="utf-8")
                if new:
                    self._file.write(json.dumps({"fingerprint": self.fingerprint}) + "\n")
            self._file.write("".join(json.dumps(r.to_json()) + "\n" for r in rows))
            self._file.flush()
            os.fsync(self._file.fileno())
        except OSError as error:
            self._abandon()
            if error.errno in DISK_ERRORS:
                raise disk_error(
                    self.path, error, "the sweep stopped; the journal keeps the points written before"
                ) from None
            raise

    def _abandon(self) -> None:
        """Forget the file after a failed write (its buffered text cannot be written either; a
        torn last line is ignored on reading)."""
        self._buffer = []
        if self._file is not None:
            try:
                self._file.close()
            except OSError:
                pass
            self._file = None

    def close(self) -> None:
        try:
            self.flush()
        finally:
            if self._file is not None:
                self._file.close()
                self._file = None

    def remove(self) -> None:
        self._buffer = []
        self.close()
        self.path.unlink(missing_ok=True)


def journal_path(output) -> Path:
    return Path(str(output) + ".journal")
