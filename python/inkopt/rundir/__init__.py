"""The run directory (docs/run-dir.md): the one owner of its files, their names, loading and checks.

Every optimisation (``inkopt slab``, ``inkopt optimize``) writes one folder; later stages (quantize, export,
evaluate) read it and add to it. All files are written atomically. Stages never build these paths themselves:
they ask a :class:`RunDir` (a named ``*_path`` accessor per file and folder; load/save methods with the checks).

``scene.npz`` is typed as a :class:`SceneRecord`: the sensor (texels), the targets, how the slab's faces map to
pictures, and the optimisation's constraints (``free_mask``, ``fixed_share``). Large objects store only
``free_mask``; :meth:`SceneRecord.fixed_share` rebuilds the fixed shares from it and from the translucency
constraint (``model.Translucency``, stored sparsely), so every reader sees the same constraints however the file
stores them. scene.npz carries ``format_version`` (``SCENE_FORMAT``); older versions are read through
``io.upgrade_format``.

Outputs tied to their inputs: quantized.npz, the slice manifest and evaluation.json record ``volume_digest``
(``io.file_digest`` of the volume.npz they were made from; the manifest and evaluation.json also
``quantized_digest``), and quantized.npz records ``labels_digest``, that of its labels file (computed as the layers
are written). :meth:`RunDir.check_quantized_current` refuses a quantized volume made from another volume.npz (a
:class:`StaleOutputError`) and labels that are not the ones written with it; a file that cannot be read is damaged
(``io.DamagedFileError``), never taken for a stale one. A run removes what it makes stale: a fresh run every
output of an earlier run in its folder (:meth:`RunDir.remove_earlier_run`), a run that writes a new volume.npz the
derived outputs not made from it (:meth:`RunDir.remove_stale`).

One job at a time writes into a run folder: every command that writes into one holds :meth:`RunDir.lock` (a lock
file, ``rundir.lock``), and taking it removes the temporary files a killed job left (``io.remove_temporaries``).
"""

from __future__ import annotations

import shutil
from contextlib import nullcontext
from pathlib import Path

import numpy as np

from ..errors import ParameterError
from ..io import (
    check_output,
    damage_of,
    damaged,
    file_digest,
    load_npz,
    package_source,
    read_json_object,
    remove_temporaries,
    save_npz,
    write_json,
)
from ..model import Volume
from .lock import LOCK_NAME, RunDirBusy, RunLock
from .quantized import LABELS_DIGEST, QUANTIZED_DIGEST, VOLUME_DIGEST, QuantizedFiles, StaleOutputError
from .records import FIXED_SHARE_MAX_ENTRIES, PREDICTIONS_FORMAT, SCENE_FORMAT, BandValues, Predictions, SceneRecord

__all__ = [
    "BandValues",
    "FIXED_SHARE_MAX_ENTRIES",
    "LABELS_DIGEST",
    "PREDICTIONS_FORMAT",
    "QUANTIZED_DIGEST",
    "SCENE_FORMAT",
    "VOLUME_DIGEST",
    "Predictions",
    "RunDir",
    "RunDirBusy",
    "SceneRecord",
    "StaleOutputError",
]

#: what to do about a damaged volume.npz
_REDO_RUN = "rerun the optimisation that wrote it ('inkopt slab' or 'inkopt optimize')"
#: the keys only an evaluation (evaluation.json or ``inkopt evaluate --out``) holds
_EVALUATION_KEYS = ("continuous", "quantized", "printer_texels", "spp")


def is_evaluation_file(path) -> bool:
    """Whether ``path`` holds an evaluation written by ``inkopt evaluate`` (a JSON object with its keys)."""
    data = read_json_object(path)
    return data is not None and all(k in data for k in _EVALUATION_KEYS)


class _RunFile:
    """A file of every run under one name: ``RunDir(d).x_path`` is ``d / name`` (whether or not it exists yet)."""

    def __init__(self, name: str, doc: str):
        self.name, self.__doc__ = name, doc

    def __get__(self, rd, owner=None):
        return self if rd is None else rd.path / self.name


class RunDir(QuantizedFiles):
    """A run directory. ``RunDir(path)`` requires it to exist; ``RunDir.create(path)`` makes it.

    Every file and folder of a run has a named accessor (``*_path``: where it is, whether or not it exists yet)
    and, for the files inkopt reads back, a load/save or read/write method with its checks."""

    VOLUME, SCENE, CHECKPOINT, REPORT = "volume.npz", "scene.npz", "checkpoint.npz", "report.json"
    QUANTIZED, EVALUATION, SLICES, LOSS_PNG = "quantized.npz", "evaluation.json", "slices", "loss.png"
    QUANTIZED_LABELS, DENSE_LABELS, GCVF = "quantized_labels.layers", "quantized_labels.npy", "slices.gcvf"
    MIXTURE_3MF, LABELS_3MF = "mixture.3mf", "quantized.3mf"
    VIEWS_PNG, PREDICTION_GLB, TARGET_GLB = "views.png", "prediction.glb", "target.glb"
    PREDICTIONS, PROOF, LOCK = "predictions.npz", "report.html", LOCK_NAME
    SPECTRAL_INKS, EVALUATION_LIGHTS = "spectral_inks.json", "evaluation_lights.json"
    SAMPLE_PREDICTIONS = "predictions_sample.npz"

    def __init__(self, path):
        self.path = Path(path)
        if not self.path.is_dir():
            raise ValueError(f"run directory {self.path} does not exist")
        self._labels_checked = None  # the labels file found to match its digest: (inode, size, mtime, digest)
        self._made = False  # made by ``create``: removed again if its lock is released with nothing in it

    @classmethod
    def create(cls, path) -> RunDir:
        """Make the folder (if needed)."""
        made = not Path(path).exists()
        Path(path).mkdir(parents=True, exist_ok=True)
        rd = cls(path)
        rd._made = made
        return rd

    # ------------------------------------------------------------------ one job at a time
    def lock(self, log=None) -> RunLock:
        """The folder's lock (``rundir.lock``), taken by ``with d.lock(log):`` around every write into it: another
        running job's lock refuses the folder in one line (``RunDirBusy``), a killed job's is taken over (``log``
        gets a line). Once taken, the temporary files of killed jobs are removed (:meth:`remove_temporaries`); a
        folder ``create`` made is removed again if the job leaves nothing in it (it failed before writing)."""
        return RunLock(self.path, log, on_acquire=lambda: self.remove_temporaries(log), on_release=self._unmake)

    def _unmake(self) -> None:
        if self._made and not any(self.path.iterdir()):
            self.path.rmdir()

    @classmethod
    def locked(cls, path, log=None, write: bool = True):
        """The lock (:meth:`lock`) of run folder ``path``, made if needed; when the caller will not ``write`` (a
        dry run), a block that holds nothing and makes no folder."""
        return cls.create(path).lock(log) if write else nullcontext()

    def lock_for(self, out, log=None):
        """:meth:`lock` if ``out`` (an output path; None: the command's default output in this folder) lies in
        this run folder, else a block that holds nothing (an output elsewhere does not write into the run)."""
        inside = out is None or Path(out).resolve().is_relative_to(self.path.resolve())
        return self.lock(log) if inside else nullcontext()

    def remove_temporaries(self, log=None) -> int:
        """Remove the temporary files (``io.is_temporary``) a killed job left in the folder and its subfolders
        (not in a run folder inside it, e.g. a coarse-to-fine run's coarse/: it has a lock of its own); only under
        the lock. Returns how many; ``log`` gets a line when there were any."""
        count, size = remove_temporaries(
            self.path, skip=lambda p: (p / self.SCENE).is_file() or (p / LOCK_NAME).exists()
        )
        if count and log is not None:
            log(f"removed {count} temporary file(s) of an interrupted command from {self.path} ({size / 1e6:.1f} MB)")
        return count

    def __str__(self) -> str:
        return str(self.path)

    # ------------------------------------------------------------------ names
    volume_path = _RunFile(VOLUME, "volume.npz: the optimised mixture.")
    scene_path = _RunFile(SCENE, "scene.npz: texels, targets, constraints (:class:`SceneRecord`).")
    checkpoint_path = _RunFile(CHECKPOINT, "checkpoint.npz: the optimiser's state for an exact resume.")
    report_path = _RunFile(REPORT, "report.json: the run's figures, times and settings.")
    quantized_path = _RunFile(QUANTIZED, "quantized.npz: the printer labels volume without its labels.")
    quantized_labels_path = _RunFile(
        QUANTIZED_LABELS, "quantized_labels.layers: the printer labels (z, y, x) uint8, deflated layer by layer."
    )
    dense_labels_path = _RunFile(
        DENSE_LABELS, "quantized_labels.npy: the printer labels (z, y, x) uint8 as inkopt wrote them before (read)."
    )
    evaluation_path = _RunFile(EVALUATION, "evaluation.json: ``inkopt evaluate``'s figures.")
    slices_path = _RunFile(SLICES, "slices/: the default folder of ``inkopt export``'s PNG slices.")
    gcvf_path = _RunFile(GCVF, "slices.gcvf: the default GrabCAD Voxel Print package of ``inkopt export``.")
    loss_picture_path = _RunFile(LOSS_PNG, "loss.png: the training loss and ΔE76 per iteration.")
    views_picture_path = _RunFile(VIEWS_PNG, "views.png: a mesh's target and predicted views.")
    prediction_glb_path = _RunFile(PREDICTION_GLB, "prediction.glb: the mesh with the predicted colours.")
    target_glb_path = _RunFile(TARGET_GLB, "target.glb: the mesh with the target colours.")
    predictions_path = _RunFile(PREDICTIONS, "predictions.npz: predicted colours per scene texel.")
    proof_path = _RunFile(PROOF, "report.html: the soft-proof page (``inkopt report``).")
    spectral_inks_path = _RunFile(SPECTRAL_INKS, "spectral_inks.json: a spectral run's ink table.")
    evaluation_lights_path = _RunFile(EVALUATION_LIGHTS, "evaluation_lights.json: a spectral run's figures by light.")
    sample_predictions_path = _RunFile(
        SAMPLE_PREDICTIONS, "predictions_sample.npz: a spectral run's predictions on an evaluation's texel sample."
    )

    def threemf_path(self, labels: bool = False) -> Path:
        """mixture.3mf (the continuous mixture) or quantized.3mf (``labels``): ``inkopt export --format 3mf``."""
        return self.path / (self.LABELS_3MF if labels else self.MIXTURE_3MF)

    def face_picture_path(self, face: str) -> Path:
        """face_<face>.png: a slab face's target | prediction | ΔE76 map."""
        return self.path / f"face_{face}.png"

    def evaluation_picture_path(self, face: str, stem: str = "evaluation") -> Path:
        """<stem>_<face>.png: a slab face's target | optimized | quantized | baselines, or (face "views") a mesh's
        rows of them seen from four sides (``inkopt evaluate``; ``stem``: the evaluation file's)."""
        return self.path / f"{stem}_{face}.png"

    def _need(self, path: Path, hint: str) -> Path:
        if not path.is_file():
            raise ValueError(f"{path} does not exist ({hint})")
        return path

    # ------------------------------------------------------------------ the continuous result
    def save_volume(self, vol: Volume) -> Path:
        vol.save(self.volume_path)
        return self.volume_path

    def save_volume_slabs(self, geometry: Volume, mixture_slabs, inks) -> Path:
        """volume.npz of ``geometry`` with a mixture given as z slabs (``Volume.save_with_mixture``)."""
        geometry.save_with_mixture(self.volume_path, mixture_slabs, inks)
        return self.volume_path

    def load_volume(self) -> Volume:
        """The optimised mixture volume (volume.npz)."""
        p = self.volume_file()
        vol = Volume.load(p)
        if vol.form != "mixture":
            raise ValueError(f"{p} holds a {vol.form} volume; this step needs a mixture volume")
        return vol

    def volume_file(self) -> Path:
        """The path of volume.npz, checked to exist and to be whole (its table of contents reads: a truncated file
        is damaged, ``io.DamagedFileError``), for stages that read it lazily."""
        p = self._need(self.volume_path, "run 'inkopt slab' or 'inkopt optimize' first")
        if reason := damage_of(p, thorough=False):
            raise damaged(p, reason, _REDO_RUN)
        return p

    # ------------------------------------------------------------------ the scene
    def save_scene(self, rec: SceneRecord) -> Path:
        save_npz(self.scene_path, rec.arrays())
        return self.scene_path

    def load_scene(self) -> SceneRecord:
        p = self._need(self.scene_path, "run 'inkopt slab' or 'inkopt optimize' first")
        return SceneRecord.from_arrays(load_npz(p, "scene file"), str(p))

    # ------------------------------------------------------------------ reports
    def write_report(self, report: dict) -> Path:
        return write_json(self.report_path, report)

    def read_report(self) -> dict:
        return self._read_json(self._need(self.report_path, "the run has not finished"), "rerun the optimisation")

    def _read_json(self, path: Path, remedy: str) -> dict:
        """A JSON object inkopt wrote; one that cannot be read is damaged (``io.DamagedFileError``)."""
        data = read_json_object(path)
        if data is None:
            raise damaged(path, damage_of(path) or "not a JSON object", remedy)
        return data

    def evaluation_target(self, path=None) -> Path:
        """Where an evaluation goes: evaluation.json, or ``path`` (``inkopt evaluate --out``), checked by
        ``io.check_output``: a file there is replaced only if it is an evaluation (``is_evaluation_file``)."""
        target = self.evaluation_path if path is None else Path(path)
        return check_output(target, is_evaluation_file, "an evaluation written by 'inkopt evaluate'")

    def evaluation_picture_targets(self, path, names) -> list[Path]:
        """The pictures an evaluation at ``path`` (None: evaluation.json) writes beside it, ``<stem>_<name>.png`` for
        each of ``names`` (a slab's faces, "views"), checked: a file there is replaced only if the evaluation file
        at ``path`` lists it among its pictures (an earlier evaluation of that name wrote it); another file (the
        run's own face_top.png for ``path`` face.json, a photo) is refused in one line."""
        target = self.evaluation_path if path is None else Path(path)
        ours = set((read_json_object(target) or {}).get("pictures") or []) if is_evaluation_file(target) else set()
        paths = [self.evaluation_picture_path(name, target.stem) for name in names]
        for p in paths:
            if p.exists() and p.name not in ours:
                raise ParameterError(
                    f"{p} exists and is not a picture of the evaluation {target.name}; refusing to replace it "
                    "(name the evaluation otherwise with `out`)"
                )
        return paths

    def write_evaluation(self, ev: dict, path: Path | None = None) -> Path:
        """evaluation.json, or ``path`` (``inkopt evaluate --out``); another kind of file there is refused
        (:meth:`evaluation_target`)."""
        return write_json(self.evaluation_target(path), ev, indent=1)

    # ------------------------------------------------------------------ outputs tied to their inputs
    def volume_digest(self) -> str | None:
        """``io.file_digest`` of volume.npz, None without one."""
        return file_digest(self.volume_path) if self.volume_path.is_file() else None

    def quantized_digest(self) -> str | None:
        """``io.file_digest`` of quantized.npz, None without one."""
        return file_digest(self.quantized_path) if self.quantized_path.is_file() else None

    def _recorded(self, path: Path) -> str | None:
        """The ``volume_digest`` an output records (quantized.npz, evaluation.json, a slice manifest), or None
        (none recorded, or the file cannot be read)."""
        if path.suffix != ".npz":
            return (read_json_object(path) or {}).get(VOLUME_DIGEST)
        try:
            with np.load(path, allow_pickle=False) as z:
                return str(z[VOLUME_DIGEST]) if VOLUME_DIGEST in z.files else None
        except Exception:  # zip and format errors alike: an unreadable output records nothing
            return None

    def check_volume_unchanged(self, recorded: str, stale: str) -> None:
        """``StaleOutputError(stale)`` unless ``recorded`` (the digest an output records of the volume.npz it was
        made from) is volume.npz's; a volume.npz that cannot be read is damaged (``io.DamagedFileError``), which
        is said first: its digest differs too."""
        if recorded == self.volume_digest():
            return
        if reason := damage_of(self.volume_file()):
            raise damaged(self.volume_path, reason, _REDO_RUN)
        raise StaleOutputError(stale)

    def _derived(self) -> list[Path]:
        """The outputs made from volume.npz: the quantized volume, its slices and package, evaluations, the
        predicted colours and the soft-proof page."""
        return [
            self.quantized_path,
            self.quantized_labels_path,
            self.dense_labels_path,
            self.slices_path,
            self.gcvf_path,
            self.threemf_path(),
            self.threemf_path(labels=True),
            self.evaluation_path,
            self.evaluation_lights_path,
            *sorted(self.path.glob("evaluation_*.png")),
            self.predictions_path,
            self.sample_predictions_path,
            self.proof_path,
        ]

    def _remove(self, paths) -> list[str]:
        gone = []
        for p in paths:
            if p.is_dir() and (p / "manifest.json").is_file():  # only inkopt's own slice folder
                shutil.rmtree(p)
            elif p.is_file():
                p.unlink()
            else:
                continue
            gone.append(p.name)
        return gone

    def remove_earlier_run(self) -> list[str]:
        """Before a fresh run (not a resume): remove every output of an earlier run in this folder (result,
        checkpoint, report, pictures and everything derived from them), which the new run would make stale.
        Returns the names removed."""
        own = [self.volume_path, self.scene_path, self.checkpoint_path, self.report_path, self.loss_picture_path]
        own += [self.views_picture_path, self.prediction_glb_path, self.target_glb_path, self.spectral_inks_path]
        return self._remove(own + sorted(self.path.glob("face_*.png")) + self._derived())

    def remove_stale(self) -> list[str]:
        """After volume.npz is written: remove the derived outputs that do not record its digest. Printer packages
        record theirs in the archive comment (``io.source_comment``): the continuous 3MF is kept if made from this
        volume.npz, the GCVF and the labels 3MF if made from a quantized.npz that is kept. Returns the names
        removed."""
        digest = self.volume_digest()
        keep = set()
        derived = (self.quantized_path, self.evaluation_path, self.evaluation_lights_path, self.predictions_path)
        derived += (self.sample_predictions_path,)
        for p in (*derived, self.slices_path / "manifest.json"):
            if p.is_file() and self._recorded(p) == digest:
                keep.add(p.parent if p.name == "manifest.json" else p)
        if (src := package_source(self.threemf_path())) and src["digest"] == digest:
            keep.add(self.threemf_path())
        if self.quantized_path in keep:
            keep.update((self.quantized_labels_path, self.dense_labels_path))
            quantized = self.quantized_digest()
            for pkg in (self.gcvf_path, self.threemf_path(labels=True)):
                if (src := package_source(pkg)) and src["digest"] == quantized:
                    keep.add(pkg)
        if self.evaluation_path in keep:
            keep.update(self.path.glob("evaluation_*.png"))
        return self._remove(p for p in self._derived() if p not in keep)

    def read_evaluation(self) -> dict | None:
        """evaluation.json, or None if the run has not been evaluated."""
        if not self.evaluation_path.is_file():
            return None
        return self._read_json(self.evaluation_path, f"run 'inkopt evaluate {self.path}' again")

    # ------------------------------------------------------------------ predicted colours
    def save_predictions(self, pred: Predictions) -> Path:
        save_npz(self.predictions_path, pred.arrays())
        return self.predictions_path

    def save_sample_predictions(self, pred: Predictions) -> Path:
        """predictions_sample.npz: ``pred`` on a texel sample (``Predictions.texels``)."""
        if pred.texels is None:
            raise ValueError("a texel sample's predictions need their texel indices")
        save_npz(self.sample_predictions_path, pred.arrays())
        return self.sample_predictions_path

    def load_sample_predictions(self) -> Predictions | None:
        """predictions_sample.npz, or None if no sampled spectral evaluation wrote one."""
        path = self.sample_predictions_path
        return Predictions.from_arrays(load_npz(path, "predictions file"), str(path)) if path.is_file() else None

    def load_predictions(self) -> Predictions | None:
        """predictions.npz, or None if neither the optimisation nor ``inkopt evaluate`` wrote one."""
        if not self.predictions_path.is_file():
            return None
        return Predictions.from_arrays(load_npz(self.predictions_path, "predictions file"), str(self.predictions_path))
