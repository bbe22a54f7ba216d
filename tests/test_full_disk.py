"""A full disk (issue 19, item 9): every output ends with exit code 2 and ``no space left on
device: PATH``, no traceback, and neither a partial file nor a temporary file behind.

Before the fix, `crawlsim run` on a 1 MB file system printed chained HDF5 tracebacks and died of
a segmentation fault (exit 139): libhdf5, once a write failed, failed again on every flush and
close. Here the disk fills in-process (a write raising ENOSPC after a budget of bytes) for the
HDF5 results file, a figure and a sweep's journal, and, when this process may mount one, on a
real 1 MB tmpfs.
"""

from __future__ import annotations

import errno
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from crawlsim.cli import main
from crawlsim.io import atomic

GAITS = Path(__file__).resolve().parents[1] / "gaits"
GAIT = """\
blocks: 3
period: 1.0
stiffness: 10.0
links: [{kind: cosine, mean: 1.0, amplitude: 0.3}, 1.0]
friction: {forward: 1.0, backward: 2.5}
simulation: {steps_per_period: 200, max_periods: 20}
"""
FULL = "no space left on device"


@pytest.fixture
def folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "g.yaml").write_text(GAIT)
    return tmp_path


def full_after(monkeypatch, budget: int) -> None:
    """HDF5 files (`crawlsim.io.atomic.GuardedFile`) on a disk that holds ``budget`` bytes."""

    class Full(atomic.GuardedFile):
        written = 0

        def _write(self, data) -> int:
            size = len(memoryview(data))
            if Full.written + size > budget:
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
            Full.written += size
            return super()._write(data)

    monkeypatch.setattr(atomic, "GuardedFile", Full)  # every HDF5 file


def left(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def full_disk_refusal(result, path: str) -> None:
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert f"{FULL}: {path}" in result.output, result.output


@pytest.mark.parametrize("budget", [0, 4096, 60_000])
def test_a_run_on_a_full_disk(folder, monkeypatch, budget):
    """At once (0 bytes: the first write), while streaming the trajectory, and later."""
    full_after(monkeypatch, budget)
    full_disk_refusal(CliRunner().invoke(main, ["run", "g.yaml", "-o", "r.h5"]), "r.h5")
    assert left(folder) == ["g.yaml"]  # neither r.h5 nor its temporary file


def test_sweep_and_optimisation_files_on_a_full_disk(folder, monkeypatch):
    full_after(monkeypatch, 2000)
    invoke = CliRunner().invoke
    full_disk_refusal(invoke(main, ["velocity", "g.yaml", "--sweep", "period=1,2", "-o", "s.h5"]), "s.h5")
    assert left(folder) == ["g.yaml", "s.h5.journal"]  # the finished points are kept
    (folder / "s.h5.journal").unlink()
    full_disk_refusal(
        invoke(main, ["optimize", "g.yaml", "--free", "links.0.phase=0:1", "--max-evaluations", "3", "-o", "o.h5"]),
        "o.h5",
    )
    assert "o.h5" not in left(folder)


def test_a_figure_on_a_full_disk(folder, monkeypatch):
    """matplotlib writes part of the PNG, then the disk is full: no truncated PNG is left."""
    from matplotlib.figure import Figure

    def savefig(self, target, *args, **kwargs):
        Path(target).write_bytes(b"\x89PNG\r\n\x1a\n partial")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    assert CliRunner().invoke(main, ["run", "g.yaml", "-o", "r.h5", "-q"]).exit_code == 0
    monkeypatch.setattr(Figure, "savefig", savefig)
    result = CliRunner().invoke(main, ["plot", "r.h5", "--only", "motion"])
    full_disk_refusal(result, str(folder / "r-motion.png"))
    assert left(folder) == ["g.yaml", "r.h5"]


def test_a_journal_on_a_full_disk(folder, monkeypatch):
    def fsync(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "fsync", fsync)
    result = CliRunner().invoke(main, ["velocity", "g.yaml", "--sweep", "period=1,2,3", "-o", "s.csv"])
    full_disk_refusal(result, "s.csv.journal")
    assert "s.csv" not in left(folder)


def _mount_tmpfs(where: Path) -> bool:
    if os.geteuid() != 0 or shutil.which("mount") is None:
        return False
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(where)], capture_output=True)
    return done.returncode == 0


def test_a_run_on_a_real_one_megabyte_file_system(tmp_path):
    """The case of the issue on a real file system (skipped where this process cannot mount a
    tmpfs): a run whose results file (about 1.8 MB) does not fit in 1 MB."""
    disk = tmp_path / "disk"
    disk.mkdir()
    if not _mount_tmpfs(disk):
        pytest.skip("cannot mount a 1 MB tmpfs here (needs root and mount)")
    try:
        done = subprocess.run(
            [
                sys.executable,
                "-m",
                "crawlsim",
                "run",
                str(GAITS / "peristalsis-4.yaml"),
                "--steps-per-period",
                "2000",
                "-o",
                str(disk / "r.h5"),
            ],
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert done.returncode == 2, (done.returncode, done.stderr[-2000:])
        assert "Traceback" not in done.stderr
        assert done.stderr.strip() == f"Error: {FULL}: {disk / 'r.h5'} (not written)"
        assert os.listdir(disk) == []
    finally:
        subprocess.run(["umount", str(disk)], capture_output=True)
