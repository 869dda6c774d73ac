"""The checkpoint file (the run directory's checkpoint.npz, ``RunDir.checkpoint_path``): what an exact resume
needs, with its format version.

Arrays (format version 1): ``format_version`` int64; ``x`` (F, N) float32, the variables; ``iteration`` int64;
``config_key`` str, the JSON object of the settings and problem a resume must match
(``Optimization.config_key``); the optimiser's ``opt_m``, ``opt_v``, ``opt_t``; the running average of the
prediction ``c_avg``, ``c_var`` (I, 3) float32 and ``c_weight`` (absent before the first iteration); and the
per-iteration history ``hist_*`` (float64, one entry per iteration from the start); the planned end of the run
``schedule_end``, ``schedule_reason``, ``schedule_converged_at`` (-1: not yet), ``schedule_gain`` (NaN: none),
``schedule_frozen`` (``optim.stopping.Schedule``; absent in a checkpoint of a run planned for its full length);
``wall_seconds``; the evaluated figures of the start ``start_figures`` and of print-shop baselines
``baseline_figures`` (baseline kind -> figures), each a JSON object in a str array (absent until measured; the
driver measures them once, ``Optimization.keep_start_figures``, so a resume does not render them again).

A file without ``format_version`` (version 0) has the same arrays; its ``config_key`` leaves out the settings at
their "off" value (no ``schedule_iterations``, ``decay`` 0, ``smooth`` 0, uniform lighting) and marks guided
smoothing with ``"smooth_where": "flat"``. The upgrade to version 1 writes those settings out, so such a
checkpoint resumes; one made before smoothing was limited to flat texels (guided smoothing without the mark)
cannot continue the same run and is refused in one line.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..errors import ParameterError
from ..io import FORMAT_KEY, FormatError, load_npz, save_npz, upgrade_format

CHECKPOINT_FORMAT = 1


@dataclass
class History:
    """Per-iteration figures of the training loss (on the running-average prediction): ``e1``-``e3`` are the
    loss terms, NaN for a term of weight 0 (not evaluated in training; the final evaluation reports all three);
    ``delta_e76`` the mean ΔE76; seconds of the whole step and of its parts."""

    loss: list = field(default_factory=list)
    e1: list = field(default_factory=list)
    e2: list = field(default_factory=list)
    e3: list = field(default_factory=list)
    delta_e76: list = field(default_factory=list)
    seconds: list = field(default_factory=list)
    render_s: list = field(default_factory=list)
    gradient_s: list = field(default_factory=list)
    loss_s: list = field(default_factory=list)
    step_s: list = field(default_factory=list)

    def append(self, **kw):
        for k, v in kw.items():
            getattr(self, k).append(float(v))

    def arrays(self) -> dict:
        return {f"hist_{k}": np.asarray(v, np.float64) for k, v in asdict(self).items()}

    @classmethod
    def keys(cls) -> list[str]:
        """The checkpoint arrays it is stored in."""
        return [f"hist_{k}" for k in asdict(cls())]

    @classmethod
    def from_arrays(cls, d) -> History:
        return cls(**{k: [float(x) for x in d[f"hist_{k}"]] for k in asdict(cls())})


def write_checkpoint(path: str | Path, arrays: dict) -> None:
    """Write ``arrays`` (the keys of the module docstring but ``format_version``) atomically, uncompressed."""
    save_npz(path, {FORMAT_KEY: np.int64(CHECKPOINT_FORMAT), **arrays}, compressed=False)


def read_checkpoint(path: str | Path) -> dict:
    """The arrays of a checkpoint file, brought to the current format version (one-line ``FormatError`` for a
    version this inkopt does not read; ValueError for a missing or unreadable file)."""
    data = load_npz(path, "checkpoint")
    return upgrade_format(
        data, kind="checkpoint", where=path, current=CHECKPOINT_FORMAT, upgrades={0: lambda d: _upgrade_0(d, path)}
    )


#: a checkpoint's scalars: their dtype kinds and least and greatest values (None: any finite value; NaN allowed
#: for the gain); the running average's weight (samples per texel) far below what overflows its update
_SCALARS = {
    "iteration": ("iu", 0, None),
    "opt_t": ("iu", 0, None),
    "c_weight": ("fiu", 0, 1e15),
    "wall_seconds": ("fiu", 0, None),
    "schedule_end": ("iu", 0, None),
    "schedule_converged_at": ("iu", -1, None),
    "schedule_gain": ("fiu", None, None),
    "schedule_frozen": ("biu", None, None),
}
#: entries present together or not at all: the running average, the planned end
_TOGETHER = (
    ("c_avg", "c_var", "c_weight"),
    ("schedule_end", "schedule_reason", "schedule_converged_at", "schedule_gain", "schedule_frozen"),
)


def check_state(d: dict, where, shapes: dict) -> None:
    """One-line ParameterError naming the checkpoint ``where`` unless its arrays ``d`` can restore a run: each
    array of ``shapes`` ({name: shape}: the run's own variables, optimiser moments and running average, which may
    be absent) of that shape, real and finite as float32 (the average non-negative); the scalars (``_SCALARS``)
    real, finite and within their bounds; the history one real entry per iteration; ``config_key``,
    ``schedule_reason`` and ``start_figures`` text, the first and last JSON."""

    def bad(what: str) -> ParameterError:
        return ParameterError(f"checkpoint {where} {what}: a damaged file; rerun without `resume`")

    missing = [k for k in ("x", "iteration", "config_key", "opt_m", "opt_v", "opt_t", *History.keys()) if k not in d]
    missing += [k for keys in _TOGETHER if any(k in d for k in keys) for k in keys if k not in d]
    if missing:
        raise bad(f"lacks {', '.join(missing)}")
    for key, shape in shapes.items():
        a = np.asarray(d.get(key, np.zeros(shape, np.float32)))
        with np.errstate(over="ignore", invalid="ignore"):
            real = a.dtype.kind in "fiu" and a.shape == tuple(shape) and np.all(np.isfinite(a.astype(np.float32)))
        if not real or (key in ("c_avg", "c_var") and np.any(a < 0)):
            raise bad(f"holds {key} {a.dtype} {a.shape}, not finite numbers of shape {tuple(shape)}")
    for key, (kinds, least, most) in _SCALARS.items():
        a = np.asarray(d.get(key, 0))
        v = float(a) if a.ndim == 0 and a.dtype.kind in kinds else np.nan
        ok = (key == "schedule_gain" and a.ndim == 0 and a.dtype.kind in kinds) or np.isfinite(v)
        if not ok or (least is not None and v < least) or (most is not None and v > most):
            raise bad(f"holds {key} {a.dtype} {a.shape} {a.reshape(-1)[:1]}")
    for key in History.keys():
        a = np.asarray(d[key])
        if a.dtype.kind not in "fiu" or a.shape != (int(d["iteration"]),) or np.any(np.isinf(a)):
            raise bad(f"holds {key} {a.dtype} {a.shape}, not one number per iteration")
    for key in ("config_key", "schedule_reason", "start_figures"):
        if key in d and (np.asarray(d[key]).dtype.kind != "U" or np.ndim(d[key]) != 0):
            raise bad(f"holds {key} as {np.asarray(d[key]).dtype} {np.shape(d[key])}, not text")
    try:
        if not isinstance(json.loads(str(d["config_key"])), dict):
            raise ValueError("not an object")
        json.loads(str(d.get("start_figures", "null")))
    except (ValueError, RecursionError) as exc:
        raise bad(f"holds text that is no JSON object ({' '.join(str(exc).split())})") from None


def _upgrade_0(data: dict, where) -> dict:
    """Version 0 -> 1: the settings a version-0 ``config_key`` leaves out, written out (module docstring)."""
    if "config_key" not in data:
        raise FormatError(f"{where} is not an inkopt checkpoint (no config_key); rerun without `resume`")
    if any(k not in data for k in History.keys()):
        raise FormatError(
            f"{where} was made by a pre-release inkopt without the whole per-iteration history; it "
            f"cannot be continued: rerun without `resume`"
        )
    try:
        key = json.loads(str(data["config_key"]))
        if not isinstance(key, dict):
            raise ValueError("not a JSON object")
    except (ValueError, RecursionError) as exc:
        raise FormatError(f"{where}: its config_key is damaged ({exc}); rerun without `resume`") from None
    if key.get("smooth") and key.get("smooth_edge") and key.get("smooth_where") != "flat":
        raise FormatError(
            f"{where} was made by a pre-release inkopt that smoothed every voxel's step; it cannot "
            f"be continued: rerun without `resume`"
        )
    key.pop("smooth_where", None)
    key.setdefault("schedule_iterations", None)
    key.setdefault("decay", 0.0)
    key.setdefault("smooth", 0.0)
    key.setdefault("lighting", "uniform")
    return {**data, "config_key": np.array(json.dumps(key, sort_keys=True))}
