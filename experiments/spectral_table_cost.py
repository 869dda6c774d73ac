"""What the baselines' spectral colour table costs to build against the RGB one: the same 16 patches (every 60th of
the 970 mixtures of vero-cmykw's table), the same error target (0.3 ΔE76), rendered by ``colour_table.render_patches``
(RGB) and ``spectral_table.render_band_patches`` (vero-cmykw@spectral, 16 bands) with the samples shared among the
band groups by their weights (the default) and equally; in one process, one after the other. Events (path segments)
and paths are counted from every render pass (deterministic: they do not depend on the machine's load), seconds are
wall time (they do).

    nice -n 10 .venv/bin/python experiments/spectral_table_cost.py

Writes experiments/results/spectral_table_cost.json.
"""

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import machine  # noqa: E402
from common import write_study as write  # noqa: E402

import inkopt.evaluation.spectral_table as st  # noqa: E402
from inkopt.evaluation.colour_table import render_patches, table_mixtures  # noqa: E402
from inkopt.model import InkTable  # noqa: E402
from inkopt.model.spectral import load_ink_table  # noqa: E402
from inkopt.render import Renderer  # noqa: E402
from inkopt.spectral.render import SpectralRenderer  # noqa: E402

COUNT = {"events": 0, "paths": 0, "spectral": False}


def _counting(cls, spectral: bool):
    """Wrap ``cls.render_pass`` to add every pass's events and paths to COUNT (a spectral render's core passes once)."""
    orig = cls.render_pass

    def render_pass(self, *a, **k):
        r = orig(self, *a, **k)
        if COUNT["spectral"] == spectral:
            COUNT["events"] += r.events
            COUNT["paths"] += r.paths
        return r

    cls.render_pass = render_pass


def main():
    table, rgb = load_ink_table("vero-cmykw@spectral"), InkTable.parse("vero-cmykw")
    rows = table_mixtures(5, 8)[::60]
    _counting(SpectralRenderer, True)
    _counting(Renderer, False)
    made = st.SpectralRenderer
    out = {"patches": len(rows), "max_stderr": 0.3, "load_average_1min_before": machine()["load_average_1min"]}
    for name in ("weighted", "equal", "rgb"):
        COUNT.update(events=0, paths=0, spectral=name != "rgb")
        t0 = time.perf_counter()
        if name == "rgb":
            render_patches(rows, rgb, rgb.g, 1.5, 2.5, 0.3, threads=2)
        else:
            if name == "equal":
                st.SpectralRenderer = lambda *a, **k: made(*a, **{**k, "weights": None})
            st.render_band_patches(rows, table, (rgb.g, 1.5), 2.5, 0.3, threads=2)
            st.SpectralRenderer = made
        out[name] = {"seconds": time.perf_counter() - t0, "events": COUNT["events"], "paths": COUNT["paths"]}
        print(name, out[name], flush=True)
    for name in ("weighted", "equal"):
        out[f"{name}_over_rgb_events"] = out[name]["events"] / out["rgb"]["events"]
    out.update(command="python experiments/spectral_table_cost.py", threads=2, **machine())
    print("wrote", write("spectral_table_cost.json", out))


if __name__ == "__main__":
    main()
