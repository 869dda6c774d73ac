"""inkopt.io: outputs appear whole (atomic rename) with the permissions of a file the user creates, not the private
0600 of the temporary file they are written to."""

import os
import stat

import numpy as np

from inkopt.io import atomic_write_bytes, save_npz


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
