"""Tests of inkopt.evaluation.options: every option of an evaluation checked in one place, errors that name the
parameter (and, on the command line, its flag), and the command line's options built in one place."""

import pytest

from inkopt.cli import build_parser
from inkopt.cli.evaluate import options_from_args
from inkopt.errors import ParameterError
from inkopt.evaluation.noise import MAX_SPP
from inkopt.evaluation.options import EvaluateOptions
from inkopt.lighting import Lighting


@pytest.mark.parametrize(
    "kw,name",
    [
        ({"spp": 0}, "spp"),
        ({"max_spp": 0}, "max_spp"),
        ({"time_budget": 0}, "time_budget"),
        ({"time_budget": float("nan")}, "time_budget"),
        ({"patch_mm": 0.0}, "patch_mm"),
        ({"patch_mm": float("inf")}, "patch_mm"),
        ({"texel_sample": 1}, "texel_sample"),
        ({"texel_sample": -3}, "texel_sample"),
        ({"sample_windows": 1}, "sample_windows"),
        ({"out": "evaluation.txt"}, "out"),
    ],
)
def test_a_bad_option_names_its_parameter(kw, name):
    with pytest.raises(ParameterError) as exc:
        EvaluateOptions(**kw)
    assert exc.value.parameters == (name,)


def test_an_unknown_method_is_refused():
    with pytest.raises(ValueError, match="unknown quantization method 'floyd'"):
        EvaluateOptions(method="floyd")


def test_the_defaults_are_the_adaptive_full_evaluation():
    o = EvaluateOptions()
    assert o.spp is None and o.max_spp == MAX_SPP and o.time_budget is None and o.baselines and o.refine
    assert o.texel_sample is None and o.out is None and o.write and o.translucency is None


def test_the_command_line_builds_the_options_in_one_place(tmp_path):
    args = build_parser().parse_args(
        ["evaluate", str(tmp_path), "--spp", "8", "--seed", "3", "--nearest", "--no-baselines", "--no-translucency"]
        + ["--texel-sample", "100", "--sample-windows", "4", "--out", str(tmp_path / "e.json"), "--method", "random"]
    )
    o = options_from_args(args)
    assert o == EvaluateOptions(
        spp=8,
        seed=3,
        refine=False,
        baselines=False,
        translucency=False,
        texel_sample=100,
        sample_windows=4,
        out=str(tmp_path / "e.json"),
        method="random",
        lighting=Lighting(),
    )
    default = options_from_args(build_parser().parse_args(["evaluate", str(tmp_path)]))
    assert default == EvaluateOptions(lighting=Lighting())
