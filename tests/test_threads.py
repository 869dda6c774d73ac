"""Thread counts are checked once (``threads.check_threads``: 1 to 4 per core) wherever one enters the library, and
by ``--threads`` while the arguments are parsed: a count of thousands or a negative one is refused in one line
before any work, nothing written."""

import os

import numpy as np
import pytest
from PIL import Image

from inkopt.cli import main
from inkopt.errors import ParameterError
from inkopt.model import InkTable, Volume
from inkopt.threads import THREADS_PER_CORE, check_threads, max_threads

TOP = THREADS_PER_CORE * (os.cpu_count() or 1)


def test_check_threads():
    assert max_threads() == TOP
    assert check_threads(None) is None and check_threads(1) == 1 and check_threads(np.int64(TOP)) == TOP
    for bad in (0, -1, TOP + 1, 10_000):
        with pytest.raises(ParameterError, match=f"threads must be between 1 and {TOP} .*, got {bad}"):
            check_threads(bad)
    for bad in (2.5, "4", True):
        with pytest.raises(ParameterError, match="must be a whole number"):
            check_threads(bad)
    with pytest.raises(ParameterError) as exc:
        check_threads(-1, "render_threads")
    assert exc.value.parameters == ("render_threads",)


def test_the_library_refuses_a_bad_count_where_it_enters():
    from inkopt.inksets.backends import make_backend
    from inkopt.model import FixedShares
    from inkopt.optim.optimizers import make_optimizer
    from inkopt.optim.param import Parameterization
    from inkopt.render import Renderer

    vol = Volume.from_mixture(
        voxel_mm=[0.0847] * 3, mixture=np.full((2, 3, 4, 5), 0.2, np.float32), inks=InkTable.parse("vero-cmykw")
    )
    for make in (
        lambda t: Renderer(vol, threads=t),
        lambda t: Parameterization("softmax", FixedShares.none((2, 3, 4), 5), t),
        lambda t: make_optimizer("adam", 0.1, (4, 5), t),
        lambda t: make_backend(threads=t),
    ):
        for bad in (-1, 10_000):
            with pytest.raises(ParameterError, match="threads must be between 1"):
                make(bad)
    assert Renderer(vol, threads=1).threads == 1


@pytest.mark.parametrize("count", ["10000", "-1", "0", "many"])
def test_the_command_line_refuses_a_bad_count_before_anything_is_written(tmp_path, capsys, count):
    Image.new("RGB", (12, 8), (200, 30, 30)).save(tmp_path / "p.png")
    out = tmp_path / "r"
    with pytest.raises(SystemExit) as exc:
        main(["slab", str(tmp_path / "p.png"), "--size-mm", "1.5x1x0.5", "--out", str(out), "--threads", count])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "argument --threads: must be" in err.splitlines()[-1]
    assert not out.exists()


def test_a_run_with_a_bad_count_writes_nothing(tmp_path):
    """The library's run refuses the count where the optimiser takes it, before any file: the folder it made for
    its lock is removed again."""
    from inkopt.optim import OptimizeConfig
    from inkopt.run import RunOptions, run_optimisation
    from inkopt.scenes import build_scene
    from inkopt.scenes.spec import SlabSpec

    Image.new("RGB", (12, 8), (200, 30, 30)).save(tmp_path / "p.png")
    scene = build_scene(SlabSpec(str(tmp_path / "p.png"), (1.5, 1.0, 0.5)), InkTable.parse("vero-cmykw"))
    with pytest.raises(ParameterError, match="threads must be between 1"):
        run_optimisation(scene, tmp_path / "r", OptimizeConfig(iterations=1), RunOptions(threads=10_000, log=print))
    assert not (tmp_path / "r").exists()
