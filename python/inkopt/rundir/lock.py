"""A run folder's lock: one job at a time writes into a run folder (docs/run-dir.md).

``RunLock(folder)`` is a context manager over the lock file ``FOLDER/.inkopt.lock``: created atomically
(``O_CREAT | O_EXCL``), holding its holder (``Holder``: pid, host, boot, the process's start, when the lock was
taken, the command line) as JSON, and removed when the holder releases it. A folder whose lock another running job
holds is refused in one line (``RunDirBusy``: the folder, the holder's pid and command). A lock whose holder no
longer runs (on this host: its pid gone or a zombie, the pid now another process's, or the machine rebooted since)
is stale and taken over with a log line; a lock of another host is never taken over (its pid cannot be checked).
The take-over runs under an ``flock`` of the folder, so of two jobs that find the same stale lock one takes it and
the other is refused. A process takes a lock it holds again freely (the fine stage of a coarse-to-fine run inside
the job's lock): only the outermost release removes it.
"""

from __future__ import annotations

import json
import os
import socket
import sys
import time
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path

LOCK_NAME = ".inkopt.lock"
#: how long a lock file may stay empty or unreadable (being written) before it counts as a killed job's
UNREADABLE_GRACE_S = 5.0

#: the locks this process holds: (pid, folder) -> how many times taken (a forked child holds none of its parent's)
_HELD: dict[tuple[int, str], int] = {}


class RunDirBusy(ValueError):
    """A run folder another running job holds (one line: the folder, the holder, what to do)."""


def _proc_stat(pid: int) -> tuple[str, int] | None:
    """(state letter, start in clock ticks after boot) of process ``pid`` from /proc; None if it has no entry."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = text[text.rindex(")") + 2 :].split()  # after "pid (command)", which may hold spaces
    return fields[0], int(fields[19])


def _boot_id() -> str | None:
    try:
        return Path("/proc/sys/kernel/random/boot_id").read_text().strip()
    except OSError:
        return None


@dataclass(frozen=True)
class Holder:
    """Who holds a lock: ``pid`` on ``host`` (``boot``: the host's boot id, ``pid_start``: the process's start in
    clock ticks after boot, where /proc tells them), ``since`` (seconds since the epoch) and ``command`` (its
    command line, shortened)."""

    pid: int
    host: str
    since: float
    command: str
    boot: str | None = None
    pid_start: int | None = None

    @classmethod
    def me(cls) -> Holder:
        stat = _proc_stat(os.getpid())
        prog = Path(sys.argv[0]) if sys.argv and sys.argv[0] else Path("python")
        command = " ".join([prog.parent.name if prog.name == "__main__.py" else prog.name, *sys.argv[1:]])
        command = command if len(command) <= 120 else command[:117] + "..."
        return cls(os.getpid(), socket.gethostname(), time.time(), command, _boot_id(), stat and stat[1])

    @classmethod
    def read(cls, path: Path) -> Holder | None:
        """The holder a lock file names, None if it cannot be read (gone, empty, being written, garbled)."""
        try:
            d = json.loads(path.read_text())
            return cls(int(d["pid"]), str(d["host"]), float(d["since"]), str(d["command"]), d["boot"], d["pid_start"])
        except (OSError, ValueError, KeyError, TypeError):
            return None

    def running(self) -> bool | None:
        """Whether the holder still runs; None if that cannot be told (another host, or no way to ask)."""
        if self.host != socket.gethostname() or os.name == "nt":
            return None
        boot = _boot_id()
        if self.boot and boot and boot != self.boot:
            return False  # the machine rebooted since
        if Path("/proc/self/stat").is_file():
            stat = _proc_stat(self.pid)
            same = stat is not None and (self.pid_start is None or stat[1] == self.pid_start)
            return same and stat[0] not in "ZX"  # a killed job not yet reaped by its parent is a zombie
        try:
            os.kill(self.pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:  # alive, another user's
            return True
        return True

    def describe(self) -> str:
        when = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(self.since))
        return f"pid {self.pid} on {self.host}, since {when}: {self.command}"


@contextmanager
def _folder_guard(folder: Path):
    """An exclusive ``flock`` of ``folder`` for the block (nothing where the platform or file system has none):
    serialises the take-overs of a stale lock. The kernel releases it when the process ends."""
    try:
        import fcntl

        fd = os.open(folder, os.O_RDONLY)
    except (ImportError, OSError):
        yield
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
        except OSError:
            pass
        yield
    finally:
        os.close(fd)


class RunLock:
    """The lock of run folder ``folder`` (module docstring), taken by ``with``. ``log``: gets the line of a stale
    lock taken over; ``on_acquire()``: called once the lock is taken by the outermost ``with`` (e.g. clearing the
    temporary files a killed job left); ``on_release()``: once the outermost ``with`` has released it."""

    def __init__(self, folder, log: Callable[[str], None] | None = None, on_acquire=None, on_release=None):
        self.folder = Path(folder)
        self.path = self.folder / LOCK_NAME
        self.log, self.on_acquire, self.on_release = log or (lambda msg: None), on_acquire, on_release
        self.holder: Holder | None = None
        self._key = (os.getpid(), str(self.folder.resolve()))

    def __enter__(self) -> RunLock:
        if _HELD.get(self._key):
            _HELD[self._key] += 1
            return self
        self._acquire()
        _HELD[self._key] = 1
        try:
            if self.on_acquire is not None:
                self.on_acquire()
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def __exit__(self, *exc) -> None:
        _HELD[self._key] -= 1
        if _HELD[self._key] == 0:
            del _HELD[self._key]
            if self.holder is not None and Holder.read(self.path) == self.holder:
                self.path.unlink(missing_ok=True)
            if self.on_release is not None:
                self.on_release()

    def _acquire(self) -> None:
        me = Holder.me()
        for _ in range(8):  # each pass: create it, or find it held (refused) or stale (removed, then again)
            try:
                fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            except FileExistsError:
                self._remove_stale()
                continue
            with os.fdopen(fd, "w") as fh:
                fh.write(json.dumps(asdict(me)) + "\n")
            self.holder = me
            return
        raise RunDirBusy(f"{self.folder} is in use: its lock {self.path} keeps coming back; try again")

    def _snapshot(self) -> tuple[Holder | None, tuple | None]:
        """The lock file's holder and identity (inode, size, change time), (None, None) if it is gone."""
        try:
            st = self.path.stat()
        except FileNotFoundError:
            return None, None
        return Holder.read(self.path), (st.st_ino, st.st_size, st.st_mtime_ns)

    def _remove_stale(self) -> None:
        """Remove the lock file if its holder no longer runs (with a log line); ``RunDirBusy`` if it does."""
        holder, ident = self._snapshot()
        if holder is None and ident is not None and time.time_ns() - ident[2] < UNREADABLE_GRACE_S * 1e9:
            time.sleep(0.05)  # being written by the job that has just created it: look again
            holder, ident = self._snapshot()
            if holder is None and ident is not None:
                raise RunDirBusy(f"{self.folder} is in use by another inkopt job (its lock {self.path} is new)")
        if ident is None:
            return  # released meanwhile
        mine = holder is not None and (holder.pid, holder.host) == (os.getpid(), socket.gethostname())
        if holder is not None and not mine and holder.running() is not False:
            raise RunDirBusy(
                f"{self.folder} is in use by another inkopt job ({holder.describe()}); wait for it to end or, if "
                f"it no longer runs, remove {self.path}"
            )
        with _folder_guard(self.folder):
            if self._snapshot() != (holder, ident):
                return  # another job took it over first: look again
            self.path.unlink(missing_ok=True)
        what = "an unreadable lock" if holder is None else f"the lock of {holder.describe()}"
        self.log(f"{self.folder}: took over {what}, a job that no longer runs")
