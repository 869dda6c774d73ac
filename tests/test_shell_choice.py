"""The shell of a mesh run given none (``footprint.fits.choose_shell``): every voxel free when that fits the memory
limit, the ``BAND_SHELL_MM`` band over a white core when only that fits (said on the run's first line, recorded in
report.json, taken by a coarse-to-fine run's both stages), a one-line refusal naming both largest heights when
neither fits; ``--shell-mm 0`` keeps every voxel free."""

import json
import re

import pytest
from helpers import SPOT

from inkopt import footprint
from inkopt.cli import build_parser, main
from inkopt.cli.jobplan import plan_job
from inkopt.cli.runargs import config_from_args, mesh_spec_from_args, run_options_from_args
from inkopt.errors import ParameterError
from inkopt.footprint import MemoryLimit, mesh_band, mesh_footprint, mesh_shape, spec_footprint
from inkopt.footprint.fits import BAND_SHELL_MM, choose_shell
from inkopt.model import InkTable
from inkopt.scenes.mesh import load_spec_mesh
from inkopt.scenes.spec import MeshSpec, spec_from_json
from inkopt.units import voxel_mm

N_INKS = 5


def _peaks(height: float) -> tuple[float, float]:
    """(every voxel free, the band) estimated peaks (bytes) of Spot at ``height`` mm."""
    free, _ = spec_footprint(MeshSpec(str(SPOT), height_mm=height), N_INKS)
    band, _ = spec_footprint(MeshSpec(str(SPOT), height_mm=height, shell_mm=BAND_SHELL_MM), N_INKS)
    assert band.peak_bytes() < free.peak_bytes()
    return free.peak_bytes(), band.peak_bytes()


def _between(height: float) -> float:
    """A limit (bytes) between the band's and every voxel free's peaks at ``height`` mm."""
    free, band = _peaks(height)
    return 0.5 * (free + band)


def _footprint_at(shape, height: float, shell):
    """The estimated footprint of a mesh of ``shape`` at ``height`` mm and 300 DPI with a shell of ``shell`` mm (None:
    every voxel free)."""
    near = mesh_band(voxel_mm(300.0), shell) if shell else footprint.DEFAULT_BAND
    return mesh_footprint(shape.scaled(height / shape.height_mm), 300.0, shell, N_INKS, near)


def test_every_voxel_free_when_it_fits():
    spec = MeshSpec(str(SPOT), height_mm=20.0)
    free, _ = _peaks(20.0)
    choice = choose_shell(spec, N_INKS, MemoryLimit(free * 1.01, "(test)"))
    assert choice.spec is spec and choice.note is None and not choice.footprint.shell


def test_the_band_when_only_it_fits():
    spec = MeshSpec(str(SPOT), height_mm=20.0)
    choice = choose_shell(spec, N_INKS, MemoryLimit(_between(20.0), "(test)"))
    assert choice.spec.shell_mm == BAND_SHELL_MM and choice.spec.core == "white"
    assert choice.spec.shell_chosen.startswith("automatic: every voxel free needs ~")
    assert choice.footprint == spec_footprint(choice.spec, N_INKS)[0]  # the band's footprint, as given by hand
    note = ParameterError(choice.note)
    assert set(note.parameters) == {"shell_mm", "core"} and "\n" not in choice.note
    assert choice.note.startswith("memory: ") and "`shell_mm` 0 forces every voxel free" in choice.note
    # the spec travels (coarse to fine, Ray) with why its shell was chosen
    assert spec_from_json(choice.spec.to_json()) == choice.spec


def test_given_shells_and_every_voxel_free_by_choice_are_kept():
    limit = MemoryLimit(_between(20.0), "(test)")
    given = MeshSpec(str(SPOT), height_mm=20.0, shell_mm=0.5)
    assert choose_shell(given, N_INKS, limit).spec is given
    with pytest.raises(ParameterError) as exc:  # every voxel free by choice: refused as before
        choose_shell(MeshSpec(str(SPOT), height_mm=20.0), N_INKS, limit, automatic=False)
    assert "shell_mm" not in exc.value.parameters and "largest `height_mm` that fits is" in exc.value.template


def test_neither_fits_refused_naming_both_heights():
    limit = MemoryLimit(0.4 * 2**30, "(test)")
    spec = MeshSpec(str(SPOT), height_mm=40.0)
    with pytest.raises(ParameterError) as exc:
        choose_shell(spec, N_INKS, limit)
    text = str(exc.value)
    band = f"shell_mm {BAND_SHELL_MM:g}"
    m = re.search(rf"largest height_mm that fits is ([0-9.]+) with every voxel free, ([0-9.]+) with {band}", text)
    assert m, text
    free_h, band_h = float(m.group(1)), float(m.group(2))
    assert 0 < free_h <= band_h < 40.0
    shape = mesh_shape(load_spec_mesh(spec))

    def peak(h, shell):
        return _footprint_at(shape, h, shell)

    assert peak(free_h, None).fits(limit.bytes) and not peak(free_h * 1.02, None).fits(limit.bytes)
    assert peak(band_h, BAND_SHELL_MM).fits(limit.bytes) and not peak(band_h * 1.02, BAND_SHELL_MM).fits(limit.bytes)
    assert re.search(rf"or dpi [0-9]+ \(every voxel free\) or [0-9]+ \({band}\) at this size", text), text


def _cli(capsys, argv):
    code = main(argv)
    printed = capsys.readouterr()
    return code, printed.out.strip().splitlines(), printed.err.strip().splitlines()


def test_dry_run_shows_the_choice_and_shell_zero_refuses(monkeypatch, capsys, tmp_path):
    monkeypatch.delenv(footprint.MEMORY_ENV, raising=False)
    gib = f"{_between(20.0) / 2**30:.4f}"
    out = tmp_path / "run"
    base = ["optimize", str(SPOT), "--height-mm", "20", "--out", str(out), "--memory-gb", gib, "--iterations", "3"]
    code, lines, _ = _cli(capsys, [*base, "--dry-run"])
    assert code == 0 and len(lines) == 2, lines
    assert lines[0].startswith("memory: every voxel free needs ~") and f"{float(gib):.1f} GiB it may use" in lines[0]
    assert "--shell-mm 0 forces every voxel free" in lines[0] and "`" not in lines[0]
    free = spec_footprint(MeshSpec(str(SPOT), height_mm=20.0, shell_mm=BAND_SHELL_MM), N_INKS)[0].free_voxels
    assert lines[1].startswith("estimate from the mesh's size") and f"{footprint._count(free)} free" in lines[1]
    assert "(--memory-gb)" in lines[1]
    code, lines, err = _cli(capsys, [*base, "--dry-run", "--shell-mm", "0"])
    assert code == 2 and len(lines) == 1 and "memory:" not in lines[0]  # the estimate, then the refusal
    assert len(err) == 1 and "largest --height-mm that fits is" in err[0] and "--shell-mm" not in err[0]
    assert not out.exists()


def test_neither_fits_on_the_command_line(monkeypatch, capsys, tmp_path):
    monkeypatch.delenv(footprint.MEMORY_ENV, raising=False)
    out = tmp_path / "run"
    argv = ["optimize", str(SPOT), "--height-mm", "40", "--out", str(out), "--memory-gb", "0.4", "--iterations", "1"]
    code, _, err = _cli(capsys, argv)
    assert code == 2 and len(err) == 1 and not out.exists(), err
    assert re.search(
        rf"largest --height-mm that fits is [0-9.]+ with every voxel free, [0-9.]+ with --shell-mm {BAND_SHELL_MM:g}",
        err[0],
    )


def test_a_run_that_does_not_fit_every_voxel_free_runs_the_band(monkeypatch, capsys, tmp_path):
    """Spot 10 mm with a limit between the two peaks, coarse to fine: both stages optimise the ``BAND_SHELL_MM``
    band, the first log line says why, report.json records it; the free voxels are those of that ``--shell-mm``."""
    monkeypatch.delenv(footprint.MEMORY_ENV, raising=False)
    out = tmp_path / "run"
    gib = f"{_between(10.0) / 2**30:.4f}"
    argv = ["optimize", str(SPOT), "--height-mm", "10", "--out", str(out), "--memory-gb", gib]
    argv += ["--iterations", "1", "--eval-spp", "1", "--coarse-dpi", "150", "--log-every", "0"]
    code, _, err = _cli(capsys, argv)
    assert code == 0, err
    assert err[0].startswith("memory: every voxel free needs ~"), err[:3]
    fine = json.loads((out / "report.json").read_text())  # the scene's entries at its top
    coarse = json.loads((out / "coarse" / "report.json").read_text())
    for scene in (fine, coarse):
        assert scene["shell_mm"] == BAND_SHELL_MM and scene["core"] == "white"
        assert scene["shell_chosen"].startswith("automatic: every voxel free needs ~")
    band = spec_footprint(MeshSpec(str(SPOT), height_mm=10.0, shell_mm=BAND_SHELL_MM), N_INKS)[0]
    assert fine["free_voxels"] == pytest.approx(band.free_voxels, rel=0.05) and fine["free_voxels"] < band.inside_voxels
    # resumed with memory to spare, the run keeps the band it started with (its checkpoint holds the band's voxels)
    argv[argv.index("--memory-gb") + 1] = "64"
    resumed = _planned_spec([*argv, "--resume"])
    assert resumed.shell_mm == BAND_SHELL_MM and resumed.shell_chosen.startswith("kept from the run resumed")
    assert _planned_spec(argv).shell_mm is None  # not resumed: the memory decides again


def _planned_spec(argv):
    """The spec ``optimize``'s plan (``cli.jobplan.plan_job``) runs for ``argv``."""
    args = build_parser().parse_args(argv)
    spec = mesh_spec_from_args(args, args.mesh)
    inks = InkTable.parse("vero-cmykw")
    return plan_job(args, spec, inks, config_from_args(args), run_options_from_args(args, 0))[0]


@pytest.mark.parametrize("gib", [16.0, 1000.0])
def test_a_grid_beyond_the_renderer_names_the_bands_largest_height(gib):
    """Spot 200 mm has more grid voxels than the renderer takes (the band has the same grid): refused in one line
    that says so, naming the largest height at which the band fits both the grid and the memory, not only every
    voxel free's."""
    limit = MemoryLimit(gib * 2**30, "(test)")
    spec = MeshSpec(str(SPOT), height_mm=200.0)
    with pytest.raises(ParameterError) as exc:
        choose_shell(spec, N_INKS, limit)
    text = str(exc.value)
    assert "\n" not in text and "more than the renderer's 2^31" in text, text
    assert ("within memory, but" in text) == (gib == 1000.0), text
    band = f"shell_mm {BAND_SHELL_MM:g}"
    m = re.search(rf"largest height_mm that fits is ([0-9.]+) with every voxel free, ([0-9.]+) with {band}", text)
    assert m, text
    band_h = float(m.group(2))
    shape = mesh_shape(load_spec_mesh(spec))

    def band_at(h):
        return _footprint_at(shape, h, BAND_SHELL_MM)

    assert 100.0 < band_h < 200.0 and band_at(band_h).fits(limit.bytes) and not band_at(band_h * 1.02).fits(limit.bytes)
