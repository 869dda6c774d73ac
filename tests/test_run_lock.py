"""One job at a time in a run folder (``rundir.RunDir.lock``): a second job is refused in one line naming the
folder and the holder's pid; the lock of a job that no longer runs (killed, or a stale file) is taken over with a
log line; taking the lock clears the temporary files a killed job left."""

import json
import os
import signal
import socket
import subprocess
import sys
import time

import pytest

from inkopt.cli import main
from inkopt.rundir import RunDir, RunDirBusy
from inkopt.rundir.lock import LOCK_NAME, Holder

# a process that takes the lock of the folder argv[1], says "held" and keeps it until its stdin closes
HOLDER = """
import sys
from inkopt.rundir import RunDir
with RunDir(sys.argv[1]).lock():
    print("held", flush=True)
    sys.stdin.read()
"""


def hold(folder):
    """A process holding ``folder``'s lock (started and holding when this returns)."""
    p = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(folder)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    assert p.stdout.readline().strip() == "held"
    return p


def dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def write_lock(folder, **kw):
    info = dict(pid=dead_pid(), host=socket.gethostname(), since=time.time() - 60, command="inkopt quantize r")
    info.update(boot=None, pid_start=None)
    info.update(kw)
    (folder / LOCK_NAME).write_text(json.dumps(info))


def test_a_second_job_is_refused_naming_the_folder_and_the_holder(tmp_path, capsys):
    d = RunDir.create(tmp_path / "r")
    holder = hold(d.path)
    try:
        with pytest.raises(RunDirBusy, match=f"{d.path} is in use by another inkopt job \\(pid {holder.pid} "):
            with d.lock():
                pass
        assert main(["quantize", str(d.path)]) == 2  # the command line: one line, before anything is read
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and f"pid {holder.pid}" in err[0] and str(d.path) in err[0]
    finally:
        holder.stdin.close()
        holder.wait()
    assert not (d.path / LOCK_NAME).exists()  # released by its holder
    with d.lock():
        assert Holder.read(d.path / LOCK_NAME).pid == os.getpid()


def test_a_killed_jobs_lock_is_taken_over_with_a_log_line(tmp_path):
    d = RunDir.create(tmp_path / "r")
    holder = hold(d.path)
    holder.send_signal(signal.SIGKILL)
    holder.wait()
    assert Holder.read(d.path / LOCK_NAME).pid == holder.pid  # left behind
    said = []
    with d.lock(said.append):
        assert Holder.read(d.path / LOCK_NAME).pid == os.getpid()
    assert len(said) == 1 and f"took over the lock of pid {holder.pid}" in said[0]
    assert not (d.path / LOCK_NAME).exists()


@pytest.mark.parametrize(
    "lock, taken",
    [
        ({}, True),  # its pid no longer runs
        ({"boot": "another-boot"}, True),  # written before the machine rebooted
        ({"pid": 1, "pid_start": -1}, True),  # the pid is another process's by now
        ({"host": "elsewhere.invalid"}, False),  # another host's: its pid cannot be checked
        ({"pid": 1}, False),  # a running process
    ],
)
def test_stale_locks_are_taken_over_and_live_ones_kept(tmp_path, lock, taken):
    d = RunDir.create(tmp_path / "r")
    write_lock(d.path, **lock)
    if taken:
        with d.lock():
            pass
        assert not (d.path / LOCK_NAME).exists()
    else:
        with pytest.raises(RunDirBusy, match="remove .*inkopt.lock"):
            with d.lock():
                pass
        assert (d.path / LOCK_NAME).exists()


def test_an_unreadable_lock_is_taken_over_only_when_old(tmp_path):
    d = RunDir.create(tmp_path / "r")
    (d.path / LOCK_NAME).write_text("")  # a job killed between creating the file and writing it, or writing now
    with pytest.raises(RunDirBusy, match="is new"):
        with d.lock():
            pass
    old = time.time() - 60
    os.utime(d.path / LOCK_NAME, (old, old))
    said = []
    with d.lock(said.append):
        pass
    assert "took over an unreadable lock" in said[0]


def test_a_process_takes_its_own_lock_again(tmp_path):
    d = RunDir.create(tmp_path / "r")
    with d.lock():
        with RunDir(d.path).lock():  # e.g. the fine stage of a coarse-to-fine run inside the job's lock
            pass
        assert Holder.read(d.path / LOCK_NAME).pid == os.getpid()  # only the outermost release removes it
    assert not (d.path / LOCK_NAME).exists()


RACER = """
import sys, time
from inkopt.rundir import RunDir, RunDirBusy
time.sleep(max(0.0, float(sys.argv[2]) - time.time()))
try:
    with RunDir(sys.argv[1]).lock():
        time.sleep(1.0)
    print("took")
except RunDirBusy:
    print("refused")
"""


def test_of_jobs_that_find_one_stale_lock_one_takes_it(tmp_path):
    d = RunDir.create(tmp_path / "r")
    write_lock(d.path)
    start = time.time() + 1.5
    procs = [
        subprocess.Popen([sys.executable, "-c", RACER, str(d.path), str(start)], stdout=subprocess.PIPE, text=True)
        for _ in range(4)
    ]
    results = sorted(p.communicate()[0].strip() for p in procs)
    assert results == ["refused"] * 3 + ["took"]


def test_taking_the_lock_removes_temporary_files_of_killed_jobs(tmp_path):
    d = RunDir.create(tmp_path / "r")
    left = [d.path / "volume.npz.abcd_123.tmp.npz", d.path / "quantized_labels.npy.zz99yy88.tmp.npy"]
    left += [d.path / "prints" / "a.gcvf.k2j4h6g8.tmp"]
    (d.path / "prints").mkdir()
    (d.path / ".slices.q1w2e3r4.tmp").mkdir()
    (d.path / ".slices.q1w2e3r4.tmp" / "slice_00000.png").write_bytes(b"x" * 1000)
    for p in left:
        p.write_bytes(b"x" * 100)
    kept = [d.path / "notes.tmp", d.path / "coarse" / "volume.npz.abcdefgh.tmp.npz"]  # not ours; a run of its own
    (d.path / "coarse").mkdir()
    (d.path / "coarse" / "scene.npz").write_bytes(b"")
    for p in kept:
        p.write_bytes(b"")
    said = []
    with d.lock(said.append):
        pass
    assert not any(p.exists() for p in left) and not (d.path / ".slices.q1w2e3r4.tmp").exists()
    assert all(p.exists() for p in kept)
    assert said == [f"removed 4 temporary file(s) of an interrupted command from {d.path} (0.0 MB)"]


def test_an_output_elsewhere_takes_no_lock(tmp_path):
    d = RunDir.create(tmp_path / "r")
    holder = hold(d.path)
    try:
        with d.lock_for(tmp_path / "elsewhere" / "x.gcvf"):
            pass
        with pytest.raises(RunDirBusy):
            with d.lock_for(d.path / "sub" / "x.gcvf"):
                pass
    finally:
        holder.stdin.close()
        holder.wait()
