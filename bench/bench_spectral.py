"""Spectral against RGB optimisation on the reference slab: cost per iteration at equal colour noise.

    nice -n 5 .venv/bin/python bench/bench_spectral.py [--bands 16] [--spp 16] [--iterations 3] [--threads 2]
        [--equal-groups] [--spot-mm 20] [--no-hero] [--no-plan] [--out NAME.json]

The spectral table is made here from the Vero RGB table by a simple rule (an assumption of this benchmark, not the
documented spectral Vero table): each ink's sigma_s and sigma_a per channel placed at 465 (B), 540 (G) and 610 nm
(R), interpolated linearly in wavelength between them and held constant beyond, sampled at ``--bands`` centres over
400-700 nm. The RGB run uses the RGB table. The spectral renders share their samples among the band groups as the
optimiser's do (``Viewing.group_weights``), or equally with ``--equal-groups``.

1. Colour noise: the reference slab scene's texels rendered once by each at the pilot ``--spp``; the noise is each
   texel's CIELAB standard error (ΔE76, delta method: ``lab_stderr``) under D65, its RMS over texels (RGB: CIELAB
   of linear sRGB; spectral: the bands' colour map under D65). The spectral samples per texel that give the RGB
   noise at ``--spp``: spp x (noise_spectral / noise_rgb)^2 rounded up (the noise's square falls as 1/spp), then
   measured again at that spp.
2. Cost: ``--iterations`` optimisation iterations (forward + loss + gradient + step) of each at those samples,
   RGB and spectral alternating ``--rounds`` times (default 2) in one process; seconds per iteration, median over
   each kind's iterations; ``rounds``: each round's medians, their ratios to RGB's and the load after it.
   ``cpu_*``: the same in process CPU seconds (every thread of the process: what the iteration itself used, far
   less moved by other processes' load than wall seconds); ``stage_seconds_per_iteration``: per kind the median
   wall seconds of the iteration's stages (forward render, loss, gradient pass, mixing and step).
   ``planned_pilot_s``: the plan's pilot in seconds, ``planned_pilot_over_rgb_iteration`` over RGB's iteration.

Two spectral renderers: one path per band and sample (the keys without "hero"), and hero paths, each carrying a
band group's three bands (``Viewing.hero``; the ``hero_*`` keys, and "hero" in the per-iteration seconds), both with
the same group weights, measured alike (``--no-hero``: the first only).

Third, band paths grouped and weighted by a pilot render of the volume (``Viewing.planned``,
``spectral.allocation``: bands ordered by the samples they need, Neyman allocation with each band's path cost; the
``planned_*`` keys, ``planned_hero`` and ``planned_effort`` the pilots' choice between hero paths and band paths
and their efforts, ``allocation.choose``; ``--no-plan``: left out). ``over_rgb_at_equal_noise``: each kind's ratio
scaled to the RGB noise exactly (x (its noise / RGB's)^2); ``events_*``: the same in path events (forward, gradient
and replay), which do not depend on the machine's load.

``--profile SPP`` (with ``--out``): where an iteration's CPU time goes, RGB at ``--spp`` against the run's plan at
SPP samples per texel (the spp at RGB's noise, from a measurement), in process CPU seconds (:func:`profile`).

``--spot-mm H``: the same on Spot scaled to H mm (its scene's start mixture for the noise renders) instead of the
reference slab. Writes bench/results/spectral_cost.json (Spot: spectral_cost_spot<H>mm.json).
"""

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import SPOT, machine, reference_slab, write  # noqa: E402

from inkopt import charts  # noqa: E402
from inkopt.color import RGB, srgb_to_linear  # noqa: E402
from inkopt.model import InkTable  # noqa: E402
from inkopt.model.spectral import SpectralInkTable  # noqa: E402
from inkopt.optim import Optimization, OptimizeConfig  # noqa: E402
from inkopt.render import Renderer  # noqa: E402
from inkopt.scenes import build_scene  # noqa: E402
from inkopt.scenes.slab import build_slab  # noqa: E402
from inkopt.scenes.spec import MeshSpec  # noqa: E402
from inkopt.spectral.lights import named_light  # noqa: E402
from inkopt.spectral.render import group_spp  # noqa: E402
from inkopt.spectral.viewing import Viewing  # noqa: E402

#: where each RGB channel's coefficients are placed (nm): R, G, B
CHANNEL_NM = np.array([610.0, 540.0, 465.0])


def spectral_from_rgb(inks: InkTable, bands: int) -> SpectralInkTable:
    """The benchmark's spectral table: each ink's R, G, B coefficients at ``CHANNEL_NM``, linear in between."""
    wl = np.linspace(400.0, 700.0, bands)
    order = np.argsort(CHANNEL_NM)
    at = lambda sig: np.array([np.interp(wl, CHANNEL_NM[order], row[order]) for row in sig])
    return SpectralInkTable(inks.names, wl, at(inks.sigma_s), at(inks.sigma_a), inks.g)


def bench_scene(spot_mm: float | None):
    """(volume of the noise renders, scene): the reference slab with its chart and zebra, or Spot at ``spot_mm``."""
    if spot_mm is not None:
        scene = build_scene(MeshSpec(str(SPOT), height_mm=spot_mm), InkTable.parse("vero-cmykw"))
        return scene.volume, scene
    lin = lambda im: srgb_to_linear(im / 255.0).astype(np.float32)
    top, bottom = lin(charts.colour_chart(708, 472)), lin(charts.zebra(177, 118))
    vol = reference_slab()
    return vol, build_slab(top, bottom, (177 * 25.4 / 300, 118 * 25.4 / 300, 30 * 25.4 / 300), vol.inks)


def colour_noise(renderer, texels, spp: int, cmap) -> float:
    """The RMS over texels of the CIELAB standard error (ΔE76) of one render of ``spp`` samples per texel."""
    return render_noise(renderer, texels, spp, cmap)[0]


def render_noise(renderer, texels, spp: int, cmap) -> tuple[float, int]:
    """:func:`colour_noise` and the render's path events."""
    res = renderer.render(texels, spp, seed=7)
    return float(np.sqrt(np.mean(cmap.lab_stderr(res.rgb, res.var_mean) ** 2))), int(res.events)


#: an iteration's stages as the optimiser's history times them (wall seconds)
STAGES = ("render_s", "loss_s", "gradient_s", "step_s")


def iteration_seconds(scene, cfg, threads, viewing, iterations: int) -> tuple[list[float], list[int], dict]:
    """Seconds and path events (forward, gradient and replay) of each of ``iterations`` optimisation iterations,
    and per iteration its process CPU seconds (``cpu_s``: every thread of this process, less sensitive to other
    processes' load than wall seconds) and its stages' wall seconds (:data:`STAGES`)."""
    run = Optimization(scene, cfg.for_scene(scene.kind), threads=threads, viewing=viewing)
    run.renderer()  # built before the clock starts (set-up is not an iteration's cost)
    events, cpu = [], []
    for _ in range(iterations):
        c0 = time.process_time()
        run.step()
        cpu.append(time.process_time() - c0)
        events.append(sum(p["events"] + p["replayed_events"] for p in run.last_passes.values() if p))
    extra = {"cpu_s": cpu, **{k: list(getattr(run.history, k)) for k in STAGES}}
    return list(run.history.seconds), events, extra


def kind_keys(name: str, noise: dict, per_it: dict, viewing, groups: int) -> dict:
    """A spectral renderer's result keys beyond the band paths' own (``name``: "hero" or "planned"; none when it
    was left out)."""
    if name not in noise:
        return {}
    pilot, spp, at = noise[name]
    out = {
        f"{name}_group_spp": group_spp(spp, viewing.group_weights(), groups),
        f"noise_dE76_{name}_at_rgb_spp": pilot,
        f"{name}_spp_equal_noise": spp,
        f"noise_dE76_{name}": at,
        f"{name}_over_rgb": ratio(per_it[name], per_it["rgb"]),
    }
    if viewing.plan is not None:
        out.update(planned_groups=[list(g) for g in viewing.plan.groups], planned_weights=list(viewing.plan.weights))
        m = viewing.plan.measured  # the pilots' choice: hero paths or band paths, by their efforts
        out.update(planned_hero=viewing.plan.hero, planned_effort={k: m[f"effort_{k}"] for k in ("bands", "hero")})
    return out


def equal_noise_ratios(noise: dict, noise_rgb: float, per_it: dict) -> dict:
    """Each spectral kind's seconds (and events) per iteration over RGB's, scaled to the RGB noise exactly: its
    measured ratio x (its noise at its equal-noise spp / RGB's)^2 (a noise's square falls as 1 / samples), which
    removes the rounding of the samples per texel to a whole number."""
    scaled = {k: ratio(per_it[k], per_it["rgb"]) for k in noise}
    return {k: None if n[2] is None else scaled[k] * (n[2] / noise_rgb) ** 2 for k, n in noise.items()}


def round_ratios(r: dict) -> dict:
    """A round's medians over RGB's: wall seconds (``over_rgb``) and process CPU seconds (``cpu_over_rgb``)."""
    out = {"over_rgb": {k: v / r["seconds_per_iteration"]["rgb"] for k, v in r["seconds_per_iteration"].items()}}
    cpu = r["cpu_seconds_per_iteration"]
    return {**out, "cpu_over_rgb": {k: v / cpu["rgb"] for k, v in cpu.items()}}


def ratio(a: float | None, b: float | None) -> float | None:
    """a / b, None when either was not measured (``--iterations 0``: renders only)."""
    return None if a is None or b is None else a / b


def measure_noise(kinds: dict, vol, tex, a, rgb: tuple[float, int], d65) -> tuple[dict, dict]:
    """Per spectral kind: (noise at --spp, spp at RGB's noise, noise there or None with --iterations 0), and its
    forward-render path events over RGB's (``rgb``: RGB's noise and events at --spp) at equal noise."""
    noise_rgb, events_rgb = rgb
    noise, render_events = {}, {}
    for name, viewing in kinds.items():
        spectral = viewing.renderer_factory(Renderer)(vol, a.threads, None)
        pilot, ev = render_noise(spectral, tex, a.spp, d65)
        # path events of a forward render at the RGB noise: both at --spp, scaled by the noise's square
        render_events[name] = ev / events_rgb * (pilot / noise_rgb) ** 2
        spp = max(1, math.ceil(a.spp * (pilot / noise_rgb) ** 2))
        noise[name] = (pilot, spp, colour_noise(spectral, tex, spp, d65) if a.iterations else None)
        del spectral
    if not a.iterations:  # renders only
        print({k: round(v, 3) for k, v in render_events.items()}, "forward-render events over RGB at equal noise")
    return noise, render_events


def alternate(scene, kinds: dict, cfgs: dict, cfg_rgb, a) -> tuple[dict, dict, list]:
    """Per kind ("rgb" and ``kinds``) every iteration's seconds and path events, RGB and the spectral kinds
    alternating ``a.rounds`` times (so a change of the machine's load falls on all), and per round each kind's
    median seconds and the load after it."""
    secs, events = {"rgb": [], **{k: [] for k in kinds}}, {"rgb": [], **{k: [] for k in kinds}}
    extra = {"rgb": {}, **{k: {} for k in kinds}}
    rounds = []
    for _ in range(a.rounds if a.iterations else 0):
        this, cpu = {}, {}
        for k, viewing in {"rgb": None, **kinds}.items():
            s, e, x = iteration_seconds(scene, cfgs.get(k, cfg_rgb), a.threads, viewing, a.iterations)
            secs[k] += s
            events[k] += e
            for name, v in x.items():
                extra[k].setdefault(name, []).extend(v)
            this[k], cpu[k] = float(np.median(s)), float(np.median(x["cpu_s"]))
        load = os.getloadavg()[0]
        rounds.append({"seconds_per_iteration": this, "cpu_seconds_per_iteration": cpu, "load_average_1min": load})
    return secs, events, rounds, extra


def pilot_only(viewing, vol, scene, a, rgb) -> dict:
    """``--pilot-only``: a run's pilots of the start (``Viewing.planned``) against one RGB render at ``--spp`` (its
    noise and events ``rgb``): the plan chosen, both pilots' efforts, the pilots' seconds, paths and events, and
    ``predicted_events_over_rgb_at_equal_noise``: each effort (ΔE76^2 x events per texel sample) over RGB's, its
    noise^2 x spp times its events per texel sample."""
    t = time.perf_counter()
    plan = viewing.planned(vol, scene.texels, a.threads).plan
    seconds, m = time.perf_counter() - t, plan.measured
    noise_rgb, events_rgb = rgb
    rgb_effort = noise_rgb**2 * a.spp * events_rgb / (len(scene.texels) * a.spp)
    return {
        "scene": f"Spot {a.spot_mm:g} mm" if a.spot_mm else "reference slab 177x118x30 voxels, chart top, zebra below",
        "texels": len(scene.texels),
        "bands": a.bands,
        "rgb_spp": a.spp,
        "noise_dE76_rgb": noise_rgb,
        "rgb_render_events": events_rgb,
        "plan": plan.to_json(),
        "planned_hero": plan.hero,
        "planned_effort": {k: m[f"effort_{k}"] for k in ("bands", "hero")},
        "predicted_events_over_rgb_at_equal_noise": {k: m[f"effort_{k}"] / rgb_effort for k in ("bands", "hero")},
        "pilot_s": seconds,
        "pilot_events_over_rgb_render": m["events"] / events_rgb,
        **machine(),
    }


def profile(viewing, vol, scene, a) -> dict:
    """``--profile N``: one iteration of RGB at ``--spp`` and one of the run's plan at N samples per texel (after a
    warm-up iteration each), profiled in process CPU seconds (every thread of this process): per kind the CPU
    seconds, the path events of its passes and the functions of most CPU time (cProfile, ``--top`` of them)."""
    import cProfile
    import pstats

    out = {}
    kinds = {"rgb": (None, a.spp), "planned": (viewing.planned(vol, scene.texels, a.threads), a.profile)}
    for name, (view, spp) in kinds.items():
        cfg = OptimizeConfig(iterations=2, spp=spp, forward_spp=spp).for_scene(scene.kind)
        run = Optimization(scene, cfg, threads=a.threads, viewing=view)
        run.renderer()
        run.step()  # warm-up
        prof, c0 = cProfile.Profile(time.process_time), time.process_time()
        prof.enable()
        run.step()
        prof.disable()
        stats = pstats.Stats(prof).stats  # {(file, line, function): (calls, ..., tottime, cumtime, callers)}
        top = sorted(stats.items(), key=lambda kv: -kv[1][2])[: a.top]
        out[name] = {
            "spp": spp,
            "cpu_s": time.process_time() - c0,
            "events": sum(p["events"] + p["replayed_events"] for p in run.last_passes.values() if p),
            "top_cpu_s": [
                {"function": f"{Path(k[0]).name}:{k[1]}({k[2]})", "calls": v[1], "cpu_s": v[2]} for k, v in top
            ],
        }
    out["cpu_over_rgb"] = out["planned"]["cpu_s"] / out["rgb"]["cpu_s"]
    out["events_over_rgb"] = out["planned"]["events"] / out["rgb"]["events"]
    out["cpu_per_event_over_rgb"] = out["cpu_over_rgb"] / out["events_over_rgb"]
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bands", type=int, default=16)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--iterations", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--rounds", type=int, default=2, help="rounds of the kinds' alternation")
    ap.add_argument("--equal-groups", action="store_true", help="every band group the pass's spp")
    ap.add_argument("--spot-mm", type=float, help="Spot at this height instead of the reference slab")
    ap.add_argument("--no-hero", action="store_true", help="leave out the hero-path spectral renderer")
    ap.add_argument("--no-plan", action="store_true", help="leave out the band paths grouped by a pilot's plan")
    ap.add_argument("--out", help="results file name in bench/results (default by the scene)")
    ap.add_argument("--pilot-only", action="store_true", help="the run's pilots and their plan only (needs --out)")
    ap.add_argument("--profile", type=int, metavar="SPP", help="profile one RGB and one planned iteration at SPP")
    ap.add_argument("--top", type=int, default=12, help="functions listed per kind with --profile")
    a = ap.parse_args()
    vol, scene = bench_scene(a.spot_mm)
    table, d65_only, tex = spectral_from_rgb(vol.inks, a.bands), (named_light("D65"),), scene.texels
    d65 = d65_only[0].colour_map(table.wavelengths_nm)
    noise_rgb, events_rgb = render_noise(Renderer(vol, a.threads), tex, a.spp, RGB)
    if a.profile:
        out = {"profile": profile(Viewing(table, d65_only), vol, scene, a), "threads": a.threads, **machine()}
        return print("wrote", write(a.out, out))
    if a.pilot_only:
        out = pilot_only(Viewing(table, d65_only), vol, scene, a, (noise_rgb, events_rgb))
        return print("wrote", write(a.out, out))
    kinds = {"spectral": Viewing(table, d65_only, weighted=not a.equal_groups, pilot=False)}  # the mid grey's weights
    if not a.no_hero:
        kinds["hero"] = Viewing(table, d65_only, weighted=not a.equal_groups, hero=True, pilot=False)
    pilot_s = None
    if not a.no_plan:
        t = time.perf_counter()
        kinds["planned"] = Viewing(table, d65_only).planned(vol, tex, a.threads)  # as a run's pilot of its start
        pilot_s = time.perf_counter() - t
    weights = kinds["spectral"].group_weights()
    noise, render_events = measure_noise(kinds, vol, tex, a, (noise_rgb, events_rgb), d65)
    cfg_rgb = OptimizeConfig(iterations=a.iterations, spp=a.spp, forward_spp=a.spp)
    cfgs = {k: OptimizeConfig(iterations=a.iterations, spp=n[1], forward_spp=n[1]) for k, n in noise.items()}
    t0 = time.perf_counter()
    secs, events, rounds, extra = alternate(scene, kinds, cfgs, cfg_rgb, a)
    per_it = {k: float(np.median(v)) if v else None for k, v in secs.items()}
    cpu_it = {k: float(np.median(x["cpu_s"])) if x else None for k, x in extra.items()}
    stages = {k: {n: float(np.median(v)) for n, v in x.items() if n != "cpu_s"} for k, x in extra.items() if x}
    ev_it = {k: float(np.median(v)) if v else None for k, v in events.items()}
    groups = len(table.group_bands())
    out = {
        "scene": f"Spot {a.spot_mm:g} mm" if a.spot_mm else "reference slab 177x118x30 voxels, chart top, zebra below",
        "texels": len(tex),
        "bands": a.bands,
        "band_groups": groups,
        "group_spp": group_spp(noise["spectral"][1], weights, groups),
        "spectral_table": "Vero RGB coefficients at 610/540/465 nm, linear in wavelength (bench rule)",
        "rgb_spp": a.spp,
        "noise_dE76_rgb": noise_rgb,
        "noise_dE76_spectral_at_rgb_spp": noise["spectral"][0],
        "spectral_spp_equal_noise": noise["spectral"][1],
        "noise_dE76_spectral": noise["spectral"][2],
        "seconds_per_iteration": per_it,
        "iteration_seconds": secs,
        "spectral_over_rgb": ratio(per_it["spectral"], per_it["rgb"]),
        **kind_keys("hero", noise, per_it, kinds.get("hero"), groups),
        **kind_keys("planned", noise, per_it, kinds.get("planned"), groups),
        "planned_pilot_s": pilot_s,
        "planned_pilot_over_rgb_iteration": ratio(pilot_s, per_it["rgb"]),
        "rounds": [{**r, **round_ratios(r)} for r in rounds],
        "over_rgb_at_equal_noise": equal_noise_ratios(noise, noise_rgb, per_it),
        "cpu_seconds_per_iteration": cpu_it,
        "iteration_cpu_seconds": {k: x.get("cpu_s", []) for k, x in extra.items()},
        "cpu_over_rgb_at_equal_noise": equal_noise_ratios(noise, noise_rgb, cpu_it),
        "stage_seconds_per_iteration": stages,
        "events_per_iteration": ev_it,
        "iteration_events": events,
        "events_over_rgb_at_equal_noise": equal_noise_ratios(noise, noise_rgb, ev_it),
        "render_events_over_rgb_at_equal_noise": render_events,
        "threads": a.threads,
        "wall_s": time.perf_counter() - t0,
        **machine(),
    }
    for k, (pilot, spp, at) in noise.items() if a.iterations else ():
        print(
            f"noise ΔE76: rgb {noise_rgb:.3f} at spp {a.spp}; {k} {pilot:.3f} at spp {a.spp}, {at:.3f} at spp {spp}; "
            f"s/iteration rgb {per_it['rgb']:.2f}, {k} {per_it[k]:.2f} ({per_it[k] / per_it['rgb']:.2f}x; "
            f"at equal noise {out['over_rgb_at_equal_noise'][k]:.2f}x, events "
            f"{out['events_over_rgb_at_equal_noise'][k]:.2f}x, "
            f"CPU seconds {out['cpu_over_rgb_at_equal_noise'][k]:.2f}x)"
        )
    name = a.out or (f"spectral_cost_spot{a.spot_mm:g}mm.json" if a.spot_mm else "spectral_cost.json")
    print("wrote", write(name, out))


if __name__ == "__main__":
    main()
