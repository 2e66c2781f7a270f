"""Every verb that writes a file writes it atomically (issue 24, item 2): a full disk, a
file-size limit or SIGKILL mid-write leaves the old file whole, never a partial one, and a
device (/dev/full, /dev/stdout) is written in place, never replaced by a regular file.

The writer is :mod:`baseparams.io.atomic`; report, export, convert (.toml, .urdf) and plot
use it. Kills are made deterministic by a child that kills itself in the middle of its own
write (after some bytes of the new content are on disk), plus a few kills at random times
of a large write, where the file must be the old or the whole new content.
"""

import errno
import os
import pathlib
import random
import resource
import signal
import stat
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from baseparams.cli.commands import main
from baseparams.errors import InputError
from baseparams.io import atomic
from baseparams.io.atomic import atomic_path, atomic_write

OLD = "OLD CONTENT\n"

# (verb arguments with {out}, file name): every verb that writes a file
WRITERS = [
    (["report", "pendulum", "--no-certify", "-o", "{out}"], "r.txt"),
    (["export", "pendulum", "--to", "python", "-o", "{out}"], "m.py"),
    (["convert", "pendulum", "-o", "{out}"], "p.toml"),
    (["convert", "pendulum", "-o", "{out}"], "p.urdf"),
    (["plot", "mechanism", "pendulum", "-o", "{out}"], "p.png"),
]
IDS = [f"{args[0]}-{name}" for args, name in WRITERS]


def leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if ".tmp" in p.name)


# ----- the writer itself ---------------------------------------------------------------------
def test_atomic_write_replaces_the_file_and_keeps_its_mode(tmp_path):
    target = tmp_path / "a.txt"
    target.write_text(OLD)
    target.chmod(0o640)
    atomic_write(target, "new\r\ntext \u00fc")
    assert target.read_bytes() == "new\r\ntext \u00fc".encode()          # UTF-8, newlines untouched
    assert stat.S_IMODE(target.stat().st_mode) == 0o640
    atomic_write(target, b"\x00\x01")
    assert target.read_bytes() == b"\x00\x01"
    assert leftovers(tmp_path) == []


def test_a_new_file_gets_the_umask_mode(tmp_path):
    old = os.umask(0o027)
    try:
        atomic_write(tmp_path / "n.txt", "x")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "n.txt").stat().st_mode) == 0o640


def test_a_failure_mid_write_keeps_the_old_file(tmp_path, monkeypatch):
    target = tmp_path / "a.txt"
    target.write_text(OLD)
    calls = []
    real = os.write

    def full_after_one_chunk(fd, data):
        calls.append(len(data))
        if len(calls) > 1:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(fd, data)

    monkeypatch.setattr(atomic.os, "write", full_after_one_chunk)
    with pytest.raises(InputError, match="cannot write: No space left on device") as caught:
        atomic_write(target, "x" * (3 << 20))
    assert caught.value.file == str(target)
    assert len(calls) == 2                        # one chunk was really written first
    assert target.read_text() == OLD and leftovers(tmp_path) == []


def test_an_exception_inside_atomic_path_keeps_the_old_file(tmp_path):
    target = tmp_path / "a.urdf"
    target.write_text(OLD)
    with pytest.raises(KeyboardInterrupt):
        with atomic_path(target) as temporary:
            assert temporary.parent == tmp_path and temporary.suffix == ".urdf"
            temporary.write_text("half")
            raise KeyboardInterrupt
    assert target.read_text() == OLD and leftovers(tmp_path) == []


def test_missing_folder_and_folder_targets_are_input_errors(tmp_path):
    with pytest.raises(InputError, match="cannot write: No such file or directory"):
        atomic_write(tmp_path / "missing" / "a.txt", "x")
    with pytest.raises(InputError, match="cannot write: it is a folder"):
        atomic_write(tmp_path, "x")


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="no /dev/full")
def test_a_device_is_written_in_place_never_replaced():
    before = os.stat("/dev/full")
    with pytest.raises(InputError, match="No space left on device"):
        atomic_write("/dev/full", "x" * 10000)
    after = os.stat("/dev/full")
    assert stat.S_ISCHR(after.st_mode) and after.st_ino == before.st_ino
    atomic_write("/dev/null", "fine")
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)
    assert atomic.is_device("/dev/stdout") and not atomic.is_device("/tmp/x.txt")


# ----- every verb: a full disk (monkeypatched), /dev/full, ulimit -f -----------------------------
@pytest.mark.parametrize("args, name", WRITERS, ids=IDS)
def test_every_verb_keeps_the_old_file_on_a_full_disk(tmp_path, monkeypatch, args, name):
    target = tmp_path / name
    target.write_text(OLD)
    real_write, real_text = os.write, pathlib.Path.write_text

    def full(fd, data):                           # half of the first chunk lands, then ENOSPC
        real_write(fd, bytes(data[:max(1, len(data) // 2)]))
        raise OSError(errno.ENOSPC, "No space left on device")

    def full_text(self, data, *a, **k):           # convert's writers write through Path.write_text
        real_text(self, data[:len(data) // 2], *a, **k)
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(atomic.os, "write", full)
    monkeypatch.setattr(pathlib.Path, "write_text", full_text)
    result = CliRunner().invoke(main, [a.replace("{out}", str(target)) for a in args])
    assert result.exit_code == 2, result.output
    assert "cannot write" in result.stderr and "No space left on device" in result.stderr
    assert "Traceback" not in result.output
    assert target.read_text() == OLD and leftovers(tmp_path) == []


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="no /dev/full")
@pytest.mark.parametrize("args", [WRITERS[0][0], WRITERS[1][0], WRITERS[4][0] + ["--format", "png"]],
                         ids=["report", "export", "plot"])
def test_dev_full_is_exit_2_and_stays_a_device(args):
    result = CliRunner().invoke(main, [a.replace("{out}", "/dev/full") for a in args])
    assert result.exit_code == 2 and "No space left on device" in result.stderr, result.output
    assert stat.S_ISCHR(os.stat("/dev/full").st_mode)


def _limit_file_size():
    resource.setrlimit(resource.RLIMIT_FSIZE, (1024, 1024))      # ulimit -f 1


@pytest.mark.parametrize("args, name", [WRITERS[0], WRITERS[1]], ids=["report", "export"])
def test_ulimit_f_keeps_the_old_file(tmp_path, args, name):
    """issue 24: ``ulimit -f 1; baseparams report pendulum --no-certify -o r.txt`` left
    1,024 bytes of a partial report."""
    target = tmp_path / name
    target.write_text(OLD)
    argv = [sys.executable, "-m", "baseparams.cli", *[a.replace("{out}", str(target)) for a in args]]
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=600, preexec_fn=_limit_file_size)
    assert proc.returncode == 2, proc.stderr
    assert "cannot write" in proc.stderr and "File too large" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert target.read_text() == OLD and leftovers(tmp_path) == []


# ----- SIGKILL mid-write ---------------------------------------------------------------------
KILL_MID_WRITE = textwrap.dedent("""
    import os, pathlib, signal, sys
    from baseparams.io import atomic
    real_write, real_text = os.write, pathlib.Path.write_text

    def die_after_some(fd, data):        # some bytes of the new content on disk, then SIGKILL
        real_write(fd, bytes(data[:max(1, len(data) // 2)]))
        os.kill(os.getpid(), signal.SIGKILL)

    def die_text(self, data, *a, **k):
        real_text(self, data[:len(data) // 2], *a, **k)
        os.kill(os.getpid(), signal.SIGKILL)

    atomic.os.write = die_after_some
    pathlib.Path.write_text = die_text
    from baseparams.cli.commands import main
    import baseparams.cli
    main(sys.argv[1:])
""")


@pytest.mark.parametrize("args, name", WRITERS, ids=IDS)
def test_sigkill_mid_write_leaves_the_old_file(tmp_path, args, name):
    """issue 24: SIGKILL while writing left 0-byte files (convert 3 of 6, plot 3 of 3)."""
    target = tmp_path / name
    target.write_text(OLD)
    argv = [sys.executable, "-c", KILL_MID_WRITE, *[a.replace("{out}", str(target)) for a in args]]
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=600)
    assert proc.returncode == -signal.SIGKILL, proc.stderr        # it really died mid-write
    assert target.read_text() == OLD
    partial = [tmp_path / n for n in leftovers(tmp_path)]
    assert len(partial) == 1 and 0 < partial[0].stat().st_size  # the new bytes went elsewhere


LARGE_WRITER = textwrap.dedent("""
    import sys
    from baseparams.io.atomic import atomic_write
    print("ready", flush=True)
    atomic_write(sys.argv[1], b"N" * (int(sys.argv[2]) << 20))
    print("done", flush=True)
""")


def test_sigkill_at_random_times_gives_the_old_or_the_whole_new_file(tmp_path):
    target = tmp_path / "big.bin"
    rng = random.Random(24)
    size_mb = 48
    seen = set()
    for _ in range(5):
        target.write_bytes(b"O" * 1000)
        proc = subprocess.Popen([sys.executable, "-c", LARGE_WRITER, str(target), str(size_mb)],
                                stdout=subprocess.PIPE, text=True)
        assert proc.stdout.readline().strip() == "ready"
        time.sleep(rng.uniform(0.0, 0.15))
        proc.kill()
        proc.wait(timeout=30)
        proc.stdout.close()
        data = target.read_bytes()
        assert data == b"O" * 1000 or data == b"N" * (size_mb << 20), len(data)
        seen.add(data[:1])
        for name in leftovers(tmp_path):
            (tmp_path / name).unlink()
    assert b"O" in seen                 # at least one kill landed mid-write
