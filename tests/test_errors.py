"""Errors that name parameters: the library's message names its parameters, the command line's names its flags."""

import pytest

from inkopt.cli import main
from inkopt.cli.common import flag_of
from inkopt.errors import ParameterError


def test_message_names_parameters_in_python_and_flags_on_the_command_line():
    e = ParameterError("`eval_spp` must be at least 1 (or leave `eval_spp` out), got 0 for `spp`")
    assert str(e) == "eval_spp must be at least 1 (or leave eval_spp out), got 0 for spp"
    assert e.parameters == ("eval_spp", "spp")
    assert e.render(flag_of) == "--eval-spp must be at least 1 (or leave --eval-spp out), got 0 for --spp"
    assert isinstance(e, ValueError)


def test_values_are_not_rewritten():
    """Only backticked identifiers are names: a path or a value with backticks or braces stays as it is."""
    e = ParameterError("`texture` a`b {x}.png: `not an identifier` is unreadable")
    assert e.parameters == ("texture",)
    assert e.render(flag_of) == "--texture a`b {x}.png: `not an identifier` is unreadable"


def test_command_line_prints_flags(capsys, tmp_path):
    code = main(["slab", str(tmp_path / "top.png"), "--size-mm", "15x10", "--out", str(tmp_path / "run")])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("inkopt: error: --size-mm must look like") and err.count("\n") == 1
    assert not (tmp_path / "run").exists()


def test_usage_errors_are_one_line_too(capsys):
    """argparse's own errors (a missing argument, a value its type refuses) end in one line and exit status 2."""
    for argv in (["slab"], ["slab", "top.png", "--size-mm", "1x1x1", "--out", "r", "--threads", "0"]):
        with pytest.raises(SystemExit) as e:
            main(argv)
        err = capsys.readouterr().err
        assert e.value.code == 2 and err.startswith("inkopt slab: error: ") and err.count("\n") == 1, err
