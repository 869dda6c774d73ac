"""Fault injection: every command that writes into a run folder (slab, quantize, export, evaluate, report) is killed
with SIGKILL at random points of its writing (just before its Nth file replacement, ``kill_at.py``) and the folder
must stay usable: the next run of the same command takes over the dead job's lock, succeeds, and leaves no
temporary file and no lock behind."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from PIL import Image

from inkopt.cli import main
from inkopt.io import is_temporary
from inkopt.rundir.lock import LOCK_NAME

KILL_AT = Path(__file__).with_name("kill_at.py")
FAST = ["--iterations", "2", "--spp", "2", "--eval-spp", "8", "--threads", "1"]
KILLS_PER_COMMAND = 2


def killed_at(k: int, argv) -> subprocess.CompletedProcess:
    """The command run in a process of its own, killed with SIGKILL just before its ``k``-th file replacement."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(__file__).parents[2] / "python"), *sys.path])}
    cmd = [sys.executable, str(KILL_AT), str(k), *map(str, argv)]
    return subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=120)


def run_counting(argv, monkeypatch, capsys) -> tuple[int, str]:
    """The command run in this process (to its end: exit status 0); (its file replacements, its stderr)."""
    calls, replace = [], os.replace
    monkeypatch.setattr(os, "replace", lambda src, dst, **kw: calls.append(dst) or replace(src, dst, **kw))
    code = main([str(a) for a in argv])
    monkeypatch.setattr(os, "replace", replace)
    err = capsys.readouterr().err
    assert code == 0, err
    return len(calls), err


def leftovers(d: Path) -> list[Path]:
    return [p for p in d.rglob("*") if is_temporary(p) or p.name == LOCK_NAME]


def test_killed_commands_leave_a_usable_run_folder(tmp_path, monkeypatch, capsys):
    rng = np.random.default_rng(20240601)
    Image.fromarray(rng.uniform(0, 255, (12, 16, 3)).astype(np.uint8)).save(tmp_path / "p.png")
    d = tmp_path / "r"
    commands = [
        ["slab", tmp_path / "p.png", "--size-mm", "2x1.5x0.5", "--out", d, *FAST],
        ["quantize", d],
        ["export", d],
        ["evaluate", d, "--spp", "4", "--no-baselines"],
        ["report", d],
    ]
    faults = []
    for argv in commands:
        run_counting(argv, monkeypatch, capsys)  # its outputs in place: later runs replace them (export: 2 renames)
        n, _ = run_counting(argv, monkeypatch, capsys)
        for k in sorted(rng.choice(np.arange(1, n + 1), size=min(KILLS_PER_COMMAND, n), replace=False)):
            killed = killed_at(int(k), argv)
            assert killed.returncode == -9, killed.stderr
            faults.append(f"{argv[0]} at write {k} of {n}")
            _, err = run_counting(argv, monkeypatch, capsys)  # the next run of the same command succeeds
            assert "took over the lock of pid" in err  # the killed job's
            assert leftovers(d) == [], faults[-1]  # its temporary files removed, the lock released
    print(f"{len(faults)} faults injected: {', '.join(faults)}")
    assert len(faults) >= len(commands)
