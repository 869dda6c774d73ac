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
``quantized_digest``). :meth:`RunDir.check_quantized_current` refuses a quantized volume made from another
volume.npz (a :class:`StaleOutputError`), and a run removes what it makes stale: a fresh run every output of an
earlier run in its folder (:meth:`RunDir.remove_earlier_run`), a run that writes a new volume.npz the derived
outputs not made from it (:meth:`RunDir.remove_stale`).
"""

from __future__ import annotations

import json
import shutil
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ..io import file_digest, load_npz, package_source, save_npz, write_json
from ..model import Volume
from ..model.labelfile import LabelFileWriter
from ..model.volume import upgrade_volume
from .records import FIXED_SHARE_MAX_ENTRIES, PREDICTIONS_FORMAT, SCENE_FORMAT, Predictions, SceneRecord

__all__ = [
    "FIXED_SHARE_MAX_ENTRIES",
    "PREDICTIONS_FORMAT",
    "QUANTIZED_DIGEST",
    "SCENE_FORMAT",
    "VOLUME_DIGEST",
    "Predictions",
    "RunDir",
    "SceneRecord",
    "StaleOutputError",
]

#: the key under which an output records the digest of the volume.npz / quantized.npz it was made from
VOLUME_DIGEST, QUANTIZED_DIGEST = "volume_digest", "quantized_digest"


class StaleOutputError(ValueError):
    """An output made from another version of the file it derives from (one line: what to run again)."""


class _RunFile:
    """A file of every run under one name: ``RunDir(d).x_path`` is ``d / name`` (whether or not it exists yet)."""

    def __init__(self, name: str, doc: str):
        self.name, self.__doc__ = name, doc

    def __get__(self, rd, owner=None):
        return self if rd is None else rd.path / self.name


class RunDir:
    """A run directory. ``RunDir(path)`` requires it to exist; ``RunDir.create(path)`` makes it.

    Every file and folder of a run has a named accessor (``*_path``: where it is, whether or not it exists yet)
    and, for the files inkopt reads back, a load/save or read/write method with its checks."""

    VOLUME, SCENE, CHECKPOINT, REPORT = "volume.npz", "scene.npz", "checkpoint.npz", "report.json"
    QUANTIZED, EVALUATION, SLICES, LOSS_PNG = "quantized.npz", "evaluation.json", "slices", "loss.png"
    QUANTIZED_LABELS, GCVF = "quantized_labels.npy", "slices.gcvf"
    MIXTURE_3MF, LABELS_3MF = "mixture.3mf", "quantized.3mf"
    VIEWS_PNG, PREDICTION_GLB, TARGET_GLB = "views.png", "prediction.glb", "target.glb"
    PREDICTIONS, PROOF = "predictions.npz", "report.html"

    def __init__(self, path):
        self.path = Path(path)
        if not self.path.is_dir():
            raise ValueError(f"run directory {self.path} does not exist")

    @classmethod
    def create(cls, path) -> RunDir:
        """Make the folder (if needed) and remove the temporary files of an earlier process that was killed while
        writing (``inkopt.io`` writes ``NAME.XXXX.tmp[.npz]`` and renames it into place)."""
        Path(path).mkdir(parents=True, exist_ok=True)
        for stale in [*Path(path).glob("*.tmp"), *Path(path).glob("*.tmp.npz")]:
            stale.unlink(missing_ok=True)
        return cls(path)

    def __str__(self) -> str:
        return str(self.path)

    # ------------------------------------------------------------------ names
    volume_path = _RunFile(VOLUME, "volume.npz: the optimised mixture.")
    scene_path = _RunFile(SCENE, "scene.npz: texels, targets, constraints (:class:`SceneRecord`).")
    checkpoint_path = _RunFile(CHECKPOINT, "checkpoint.npz: the optimiser's state for an exact resume.")
    report_path = _RunFile(REPORT, "report.json: the run's figures, times and settings.")
    quantized_path = _RunFile(QUANTIZED, "quantized.npz: the printer labels volume without its labels.")
    quantized_labels_path = _RunFile(QUANTIZED_LABELS, "quantized_labels.npy: the printer labels (z, y, x) uint8.")
    evaluation_path = _RunFile(EVALUATION, "evaluation.json: ``inkopt evaluate``'s figures.")
    slices_path = _RunFile(SLICES, "slices/: the default folder of ``inkopt export``'s PNG slices.")
    gcvf_path = _RunFile(GCVF, "slices.gcvf: the default GrabCAD Voxel Print package of ``inkopt export``.")
    loss_picture_path = _RunFile(LOSS_PNG, "loss.png: the training loss and ΔE76 per iteration.")
    views_picture_path = _RunFile(VIEWS_PNG, "views.png: a mesh's target and predicted views.")
    prediction_glb_path = _RunFile(PREDICTION_GLB, "prediction.glb: the mesh with the predicted colours.")
    target_glb_path = _RunFile(TARGET_GLB, "target.glb: the mesh with the target colours.")
    predictions_path = _RunFile(PREDICTIONS, "predictions.npz: predicted colours per scene texel.")
    proof_path = _RunFile(PROOF, "report.html: the soft-proof page (``inkopt report``).")

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
        p = self._need(self.volume_path, "run 'inkopt slab' or 'inkopt optimize' first")
        vol = Volume.load(p)
        if vol.form != "mixture":
            raise ValueError(f"{p} holds a {vol.form} volume; this step needs a mixture volume")
        return vol

    # ------------------------------------------------------------------ the scene
    def save_scene(self, rec: SceneRecord) -> Path:
        save_npz(self.scene_path, rec.arrays())
        return self.scene_path

    def load_scene(self) -> SceneRecord:
        p = self._need(self.scene_path, "run 'inkopt slab' or 'inkopt optimize' first")
        return SceneRecord.from_arrays(load_npz(p, "scene file"), str(p))

    # ------------------------------------------------------------------ printer labels
    def save_quantized(self, vol: Volume, volume_digest: str | None = None) -> Path:
        """quantized.npz (everything but the labels) + quantized_labels.npy (the labels, copied layer by layer);
        ``volume_digest``: that of the volume.npz it was made from."""
        with self.quantized_writer(vol, vol.shape, volume_digest=volume_digest) as w:
            for k in range(vol.shape[0]):
                w[k] = vol.labels[k]
        return self.quantized_path

    @contextmanager
    def quantized_writer(self, meta: Volume, shape, normals=None, volume_digest: str | None = None):
        """Write the quantized volume one printer layer at a time: ``with d.quantized_writer(meta, shape) as w:
        w[k] = layer`` (k = 0, 1, ...; ``model.labelfile.LabelFileWriter``). ``meta``: a labels Volume giving
        everything but the labels (voxel size, inks, settings; its own labels are ignored); ``normals``: the
        printer grid's ``SurfaceNormals`` or None. On success
        the labels file replaces quantized_labels.npy and then quantized.npz is written (the old quantized.npz is
        removed first, so a crash never pairs an old quantized.npz with new labels). ``volume_digest``: the
        ``io.file_digest`` of the volume.npz the labels are made from, recorded as ``volume_digest``."""
        arrays = {k: v for k, v in meta.to_arrays().items() if k != "labels"}
        if normals is not None:
            arrays.update(normal_index=normals.index, normal_vectors=normals.vectors)
        if volume_digest is not None:
            arrays[VOLUME_DIGEST] = np.array(volume_digest)
        w = LabelFileWriter(self.quantized_labels_path, shape)
        try:
            yield w
            self.quantized_path.unlink(missing_ok=True)
            w.commit()
        except BaseException:
            w.abort()
            raise
        save_npz(
            self.quantized_path,
            {
                **arrays,
                "labels_file": np.array(self.QUANTIZED_LABELS),
                "labels_shape": np.asarray(w.shape, np.int64),
                "label_counts": w.counts,
            },
        )

    def volume_file(self) -> Path:
        """The path of volume.npz (checked to exist), for stages that read it lazily."""
        return self._need(self.volume_path, "run 'inkopt slab' or 'inkopt optimize' first")

    def has_quantized(self) -> bool:
        return self.quantized_path.is_file()

    def load_quantized(self) -> Volume:
        p = self._need(self.quantized_path, f"run 'inkopt quantize {self.path}' first")
        vol = Volume.from_arrays(upgrade_volume(load_npz(p, "quantized volume"), p, quantized=True), p)
        if vol.form != "labels":
            raise ValueError(f"{p} holds a {vol.form} volume, not printer labels")
        return vol

    # ------------------------------------------------------------------ reports
    def write_report(self, report: dict) -> Path:
        return write_json(self.report_path, report)

    def read_report(self) -> dict:
        return json.loads(self._need(self.report_path, "the run has not finished").read_text())

    def write_evaluation(self, ev: dict, path: Path | None = None) -> Path:
        """evaluation.json, or ``path`` (``inkopt evaluate --out``)."""
        return write_json(self.evaluation_path if path is None else path, ev, indent=1)

    # ------------------------------------------------------------------ outputs tied to their inputs
    def volume_digest(self) -> str | None:
        """``io.file_digest`` of volume.npz, None without one."""
        return file_digest(self.volume_path) if self.volume_path.is_file() else None

    def quantized_digest(self) -> str | None:
        """``io.file_digest`` of quantized.npz, None without one."""
        return file_digest(self.quantized_path) if self.quantized_path.is_file() else None

    def _recorded(self, path: Path) -> str | None:
        """The ``volume_digest`` an output records (quantized.npz, evaluation.json, a slice manifest), or None."""
        try:
            if path.suffix == ".npz":
                with np.load(path, allow_pickle=False) as z:
                    return str(z[VOLUME_DIGEST]) if VOLUME_DIGEST in z.files else None
            return json.loads(path.read_text()).get(VOLUME_DIGEST)
        except (OSError, ValueError, KeyError, AttributeError):
            return None

    def check_quantized_current(self) -> None:
        """StaleOutputError unless quantized.npz was made from the current volume.npz: it records that file's
        digest, or (a file written without one, by an older inkopt or a script) is not older than volume.npz.
        Nothing to check without either file."""
        if not (self.has_quantized() and self.volume_path.is_file()):
            return
        rec, again = self._recorded(self.quantized_path), f"run 'inkopt quantize {self.path}' again"
        if rec is None and self.volume_path.stat().st_mtime > self.quantized_path.stat().st_mtime:
            raise StaleOutputError(
                f"{self.quantized_path} is older than volume.npz and does not record which volume.npz it was "
                f"made from; {again}"
            )
        if rec is not None and rec != self.volume_digest():
            raise StaleOutputError(
                f"{self.quantized_path} was made from another volume.npz than the one in {self.path} (the run was "
                f"redone or continued after quantizing); {again}"
            )

    def _derived(self) -> list[Path]:
        """The outputs made from volume.npz: the quantized volume, its slices and package, evaluations, the
        predicted colours and the soft-proof page."""
        return [
            self.quantized_path,
            self.quantized_labels_path,
            self.slices_path,
            self.gcvf_path,
            self.threemf_path(),
            self.threemf_path(labels=True),
            self.evaluation_path,
            *sorted(self.path.glob("evaluation_*.png")),
            self.predictions_path,
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
        own += [self.views_picture_path, self.prediction_glb_path, self.target_glb_path]
        return self._remove(own + sorted(self.path.glob("face_*.png")) + self._derived())

    def remove_stale(self) -> list[str]:
        """After volume.npz is written: remove the derived outputs that do not record its digest. Printer packages
        record theirs in the archive comment (``io.source_comment``): the continuous 3MF is kept if made from this
        volume.npz, the GCVF and the labels 3MF if made from a quantized.npz that is kept. Returns the names
        removed."""
        digest = self.volume_digest()
        keep = set()
        for p in (self.quantized_path, self.evaluation_path, self.predictions_path, self.slices_path / "manifest.json"):
            if p.is_file() and self._recorded(p) == digest:
                keep.add(p.parent if p.name == "manifest.json" else p)
        if (src := package_source(self.threemf_path())) and src["digest"] == digest:
            keep.add(self.threemf_path())
        if self.quantized_path in keep:
            keep.add(self.quantized_labels_path)
            quantized = self.quantized_digest()
            for pkg in (self.gcvf_path, self.threemf_path(labels=True)):
                if (src := package_source(pkg)) and src["digest"] == quantized:
                    keep.add(pkg)
        if self.evaluation_path in keep:
            keep.update(self.path.glob("evaluation_*.png"))
        return self._remove(p for p in self._derived() if p not in keep)

    def read_evaluation(self) -> dict | None:
        """evaluation.json, or None if the run has not been evaluated."""
        return json.loads(self.evaluation_path.read_text()) if self.evaluation_path.is_file() else None

    # ------------------------------------------------------------------ predicted colours
    def save_predictions(self, pred: Predictions) -> Path:
        save_npz(self.predictions_path, pred.arrays())
        return self.predictions_path

    def load_predictions(self) -> Predictions | None:
        """predictions.npz, or None if neither the optimisation nor ``inkopt evaluate`` wrote one."""
        if not self.predictions_path.is_file():
            return None
        return Predictions.from_arrays(load_npz(self.predictions_path, "predictions file"), str(self.predictions_path))
