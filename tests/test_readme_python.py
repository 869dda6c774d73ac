"""The README's Python examples run as they are written (in a temporary folder): the whole pipeline through the
typed bundles, then the render example on the volume it wrote."""

import re

from helpers import REPO


def _blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", (REPO / "README.md").read_text(), re.S)


def test_the_readme_python_examples_run(tmp_path, monkeypatch, capsys):
    blocks = _blocks()
    pipeline = next(b for b in blocks if "run_optimisation" in b)
    render = next(b for b in blocks if "Renderer(" in b)
    monkeypatch.chdir(tmp_path)
    exec(compile(pipeline, "README.md", "exec"), {})
    continuous, printed = (float(v) for v in capsys.readouterr().out.strip().splitlines()[-1].split())
    assert 0 < continuous < 100 and 0 < printed < 100
    assert (tmp_path / "run" / "evaluation.json").is_file()
    exec(compile(render, "README.md", "exec"), {})
    assert capsys.readouterr().out.startswith("(")  # the (I, 3) shape of the rendered texels
