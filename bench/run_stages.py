"""A whole `inkopt` command's peak resident memory stage by stage: runs ``python -m inkopt.cli ARGS`` in this
process with marks around the run driver's stages (the optimisation's set-up, each renderer build, render, metrics,
the baseline's variables, each step, the result's files; ``evaluate``'s continuous result, quantized labels,
printer texels, each printed render and the figures), and at each mark reads the peak since the previous one
(/proc/self/status VmHWM) and resets it (``/proc/self/clear_refs`` 5), so each stage's own peak is measured, not
sampled.

    python bench/run_stages.py OUT.json optimize spot.obj --height-mm 60 --shell-mm 1 ...

OUT.json: ``marks``, in order: ``{"mark": "enter X" | "exit X", "peak_gib": peak since the previous mark,
"rss_gib": resident at the mark, "seconds": since the start}``; ``peak_gib`` the whole command's (VmHWM is reset,
so the maximum of the marks' peaks); ``command``. The stages wrapped are named in ``STAGES``. Used by
``bench_footprint.py run --stages``.
"""

from __future__ import annotations

import functools
import json
import sys
import time
from pathlib import Path

#: (module, object, attribute) of each function whose call is a stage
STAGES = (
    ("inkopt.optim.loop", "Optimization", "__init__"),
    ("inkopt.optim.loop", "Optimization", "renderer"),
    ("inkopt.optim.loop", "Optimization", "initial_variables"),
    ("inkopt.optim.loop", "Optimization", "step"),
    ("inkopt.optim.loop", "Optimization", "finish"),
    ("inkopt.optim.loop", "Optimization", "release_unread_operators"),
    ("inkopt.runfigures", None, "adaptive_render"),
    ("inkopt.runfigures", None, "prediction_metrics"),
    ("inkopt.run", None, "keep_baseline_figures"),
    ("inkopt.run", None, "_prepare"),
    ("inkopt.run", None, "estimate_run"),
    ("inkopt.rundir", "RunDir", "save_scene"),
    ("inkopt.run", None, "_iterate"),
    ("inkopt.evaluation.baselines", None, "_nearest_centred"),
    ("inkopt.optim.param", None, "layers_free_mixture"),
    ("inkopt.run", None, "_write_result_files"),
    ("inkopt.run", None, "_report"),
    ("inkopt.scenes.mesh", None, "build_mesh_scene"),
    ("inkopt.evaluation.evaluate", None, "_mixture_results"),
    ("inkopt.evaluation.evaluate", None, "_render_continuous"),
    ("inkopt.evaluation.evaluate", None, "_quantized_volume"),
    ("inkopt.evaluation.evaluate", None, "_printed_results"),
    ("inkopt.evaluation.evaluate", None, "_render_printed"),
    ("inkopt.evaluation.evaluate", None, "_figures"),
    ("inkopt.evaluation.printed", "PrintedRenderer", "__init__"),
)


def _status_kib(field: str) -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    return 0


class Marks:
    """The marks so far; ``mark(name)`` records the peak since the last mark, resets it and rewrites ``out`` (JSON:
    the marks so far, readable while the command runs)."""

    def __init__(self, out: Path, command: list[str]):
        self.t0 = time.perf_counter()
        self.out, self.command = out, command
        self.marks: list[dict] = []
        self.status: int | None = None

    def mark(self, name: str) -> None:
        peak = _status_kib("VmHWM") / 2**20
        rss = _status_kib("VmRSS") / 2**20
        seconds = time.perf_counter() - self.t0
        self.marks.append({"mark": name, "peak_gib": round(peak, 4), "rss_gib": round(rss, 4), "seconds": seconds})
        Path("/proc/self/clear_refs").write_text("5")  # the peak from here on is the next stage's
        peak = max(m["peak_gib"] for m in self.marks)
        record = {"command": self.command, "exit_status": self.status, "peak_gib": peak, "marks": self.marks}
        self.out.write_text(json.dumps(record))


def _wrap(marks: Marks, owner, attr: str, name: str) -> None:
    fn = getattr(owner, attr)

    @functools.wraps(fn)
    def wrapped(*args, **kwargs):
        marks.mark(f"enter {name}")
        try:
            return fn(*args, **kwargs)
        finally:
            marks.mark(f"exit {name}")

    setattr(owner, attr, wrapped)


def main(argv: list[str]) -> None:
    import importlib

    out, args = Path(argv[0]), argv[1:]
    marks = Marks(out, args)
    for module, cls, attr in STAGES:
        mod = importlib.import_module(module)
        owner = getattr(mod, cls) if cls else mod
        _wrap(marks, owner, attr, f"{cls or module.rsplit('.', 1)[1]}.{attr}")
    from inkopt.cli import main as cli_main  # after the wrapping, which the CLI's modules then see

    marks.mark("start")
    status = 1
    try:
        status = cli_main(args) or 0
    except SystemExit as e:
        status = e.code if isinstance(e.code, int) else 1
    finally:
        marks.status = status
        marks.mark("end")
    sys.exit(status)


if __name__ == "__main__":
    main(sys.argv[1:])
