"""inkopt.io: outputs appear whole (atomic rename) with the permissions of a file the user creates, not the private
0600 of the temporary file they are written to."""

import os
import stat

import numpy as np

from inkopt.io import atomic_file, atomic_write_bytes, save_npz


def test_outputs_have_the_users_default_permissions(tmp_path):
    old = os.umask(0o022)
    try:
        atomic_write_bytes(tmp_path / "a.bin", b"x")
        save_npz(tmp_path / "b.npz", {"a": np.zeros(3)})
    finally:
        os.umask(old)
    for name in ("a.bin", "b.npz"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == 0o644, name
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.bin", "b.npz"]  # no temporary file left


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    path = tmp_path / "out.bin"
    atomic_write_bytes(path, b"old")
    try:
        with atomic_file(path) as fh:
            fh.write(b"half of the new")
            raise KeyboardInterrupt  # an interruption part-way
    except KeyboardInterrupt:
        pass
    assert path.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["out.bin"]
