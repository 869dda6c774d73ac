"""A run's printer labels (docs/run-dir.md): quantized.npz (everything but the labels, and the digests of the files
they belong with) beside the labels file (``model.labelfile``: quantized_labels.layers, each layer deflated; a run
quantized by an older inkopt has quantized_labels.npy, which is read as before), written one printer layer at a
time and read back checked. ``QuantizedFiles`` is the part of ``rundir.RunDir`` that owns them."""

from __future__ import annotations

import json
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..io import DamagedFileError, damage_of, damaged, file_digest, load_npz, save_npz
from ..model import Volume
from ..model.inks import InkTable
from ..model.labelfile import LabelFileWriter, LabelLayersWriter, load_label_file
from ..model.volume import upgrade_volume

#: the key under which an output records the digest of the volume.npz / quantized.npz it was made from
VOLUME_DIGEST, QUANTIZED_DIGEST = "volume_digest", "quantized_digest"
#: the key under which quantized.npz records the digest of its labels file
LABELS_DIGEST = "labels_digest"
#: the key under which quantized.npz records the compensation a run chose (JSON text)
COMPENSATION_CHOICE = "compensation_choice"


class StaleOutputError(ValueError):
    """An output made from another version of the file it derives from (one line: what to run again)."""


@dataclass(frozen=True)
class QuantizedLayers:
    """A run's printer labels for the output formats: ``labels`` uint8 (Z, Y, X) read a layer at a time
    (``labels[k]``), ``voxel_mm`` (x, y, z) mm of a printer voxel, ``inks`` the ``InkTable``."""

    labels: object
    voxel_mm: np.ndarray
    inks: InkTable


class QuantizedFiles:
    """quantized.npz and the printer labels file (quantized_labels.layers; quantized_labels.npy from an older inkopt) of
    a run directory: written (``quantized_writer``), read
    (``load_quantized``) and checked (``check_quantized_current``). A part of ``RunDir``, whose names and
    ``check_volume_unchanged`` it uses."""

    def save_quantized(self, vol: Volume, volume_digest: str | None = None) -> Path:
        """quantized.npz (everything but the labels) + quantized_labels.layers (the labels, copied layer by layer);
        ``volume_digest``: that of the volume.npz it was made from."""
        with self.quantized_writer(vol, vol.shape, volume_digest=volume_digest) as w:
            for k in range(vol.shape[0]):
                w[k] = vol.labels[k]
        return self.quantized_path

    @contextmanager
    def quantized_writer(self, meta: Volume, shape, normals=None, volume_digest: str | None = None, dense=False):
        """Write the quantized volume one printer layer at a time: ``with d.quantized_writer(meta, shape) as w:
        w[k] = layer`` (k = 0, 1, ...; ``model.labelfile.LabelLayersWriter``, or with ``dense`` the version-1
        ``LabelFileWriter`` into quantized_labels.npy; the other form's file is removed). ``meta``: a labels Volume
        giving everything but the labels (voxel size, inks, settings; its own labels are ignored); ``normals``: the
        printer grid's ``SurfaceNormals`` or None. On success the labels file replaces the earlier one (of either
        form) and then quantized.npz is written (the old quantized.npz is
        removed first, so a crash never pairs an old quantized.npz with new labels), recording the labels file's
        digest (``labels_digest``, computed as the layers are written). ``volume_digest``: the ``io.file_digest``
        of the volume.npz the labels are made from, recorded as ``volume_digest``."""
        arrays = {k: v for k, v in meta.to_arrays().items() if k != "labels"}
        if normals is not None:
            arrays.update(normal_index=normals.index, normal_vectors=normals.vectors)
        if volume_digest is not None:
            arrays[VOLUME_DIGEST] = np.array(volume_digest)
        path, other = self.quantized_labels_path, self.dense_labels_path
        if dense:
            path, other = other, path
        w = (LabelFileWriter if dense else LabelLayersWriter)(path, shape)
        try:
            yield w
            self.quantized_path.unlink(missing_ok=True)
            w.commit()
        except BaseException:
            w.abort()
            raise
        other.unlink(missing_ok=True)
        save_npz(
            self.quantized_path,
            {
                **arrays,
                "labels_file": np.array(path.name),
                "labels_shape": np.asarray(w.shape, np.int64),
                "label_counts": w.counts,
                LABELS_DIGEST: np.array(w.digest),
            },
        )

    def adopt_quantized(self, other) -> None:
        """Make another run directory's printer labels this run's: ``other`` (a ``RunDir`` on the same file
        system, written by ``quantized_writer`` from this run's volume.npz) gives up its labels file and
        quantized.npz, which replace this run's in the order ``quantized_writer`` writes them (quantized.npz
        removed first, the labels file renamed into place, then quantized.npz), so a crash never pairs an old
        quantized.npz with new labels."""
        labels = other.path / Path(str(other._quantized_arrays()["labels_file"])).name
        if not labels.is_file():
            raise ValueError(f"{other.quantized_path} names no labels file beside it")
        self.quantized_path.unlink(missing_ok=True)
        for path in (self.quantized_labels_path, self.dense_labels_path):
            if path.name != labels.name:
                path.unlink(missing_ok=True)
        labels.replace(self.path / labels.name)
        other.quantized_path.replace(self.quantized_path)

    def record_compensation_choice(self, choice: dict) -> None:
        """Keep what ``inkopt quantize --compensate-auto`` chose (``evaluation.halftone_choice``, JSON values) in
        quantized.npz as ``compensation_choice``: the file is written again atomically with it, the labels file
        untouched."""
        save_npz(self.quantized_path, {**self._quantized_arrays(), COMPENSATION_CHOICE: np.array(json.dumps(choice))})

    def compensation_choice(self) -> dict:
        """``{"compensation_choice": {...}}`` where quantized.npz records the run's choice, else ``{}``."""
        got = self._quantized_arrays([COMPENSATION_CHOICE]).get(COMPENSATION_CHOICE)
        return {} if got is None else {COMPENSATION_CHOICE: json.loads(str(got))}

    def has_quantized(self) -> bool:
        return self.quantized_path.is_file()

    def load_quantized(self, layered: bool = False) -> Volume:
        """The printer labels volume (quantized.npz, its labels decoded from quantized_labels.layers, or with
        ``layered`` read from it a layer at a time; memory-mapped from an older run's quantized_labels.npy),
        checked: a file that cannot be read, or labels that are not the ones written with it, are damaged."""
        p = self._need(self.quantized_path, f"run 'inkopt quantize {self.path}' first")
        arrays = self._quantized_arrays()
        self._check_labels(arrays)
        vol = Volume.from_arrays(upgrade_volume(arrays, p, quantized=True), p, layered=layered)
        if vol.form != "labels":
            raise ValueError(f"{p} holds a {vol.form} volume, not printer labels")
        return vol

    def quantized_layers(self) -> QuantizedLayers:
        """The printer labels as the formats read them, one layer at a time, without a Volume: the labels file
        checked as ``load_quantized`` checks it, memory-mapped (version 1) or decoded per layer (version 2,
        ``model.labelfile.LabelLayers``), with the printer voxel size and the ink table from quantized.npz."""
        p = self._need(self.quantized_path, f"run 'inkopt quantize {self.path}' first")
        arrays = self._quantized_arrays()
        self._check_labels(arrays)
        arrays = upgrade_volume(arrays, p, quantized=True)
        if "labels_file" not in arrays or "labels_shape" not in arrays:
            raise ValueError(f"{self.quantized_path} names no labels file; {self._quantize_again()}")
        name = Path(str(arrays["labels_file"])).name
        labels = load_label_file(self.path / name, arrays["labels_shape"], layered=True)
        return QuantizedLayers(labels, np.asarray(arrays["voxel_mm"], np.float64), InkTable.from_arrays(arrays))

    def _quantize_again(self) -> str:
        return f"run 'inkopt quantize {self.path}' again"

    def _quantized_arrays(self, keys=None) -> dict:
        """quantized.npz's arrays (``keys``: only those of them it holds); a file that cannot be read is damaged
        (``io.DamagedFileError``)."""
        p = self.quantized_path
        try:
            if keys is None:
                return load_npz(p, "quantized volume")
            with np.load(p, allow_pickle=False) as z:
                return {k: z[k] for k in keys if k in z.files}
        except Exception as exc:  # zip and format errors alike
            if reason := damage_of(p):
                raise damaged(p, reason, self._quantize_again()) from None
            if isinstance(exc, ValueError):  # load_npz's one line (e.g. pickled contents)
                raise
            raise ValueError(f"{p} is not a readable quantized volume ({type(exc).__name__}: {exc})") from None

    def _check_labels(self, arrays: dict) -> None:
        """The labels file must be the one quantized.npz records the digest of (``labels_digest``; a quantized.npz
        written before it recorded one is read as before, unchecked): else it is damaged. Read once per file
        version (its inode, size and change time)."""
        recorded = arrays.get(LABELS_DIGEST)
        if recorded is None or "labels_file" not in arrays:
            return
        path = self.path / Path(str(arrays["labels_file"])).name
        if not path.is_file():
            return  # Volume.from_arrays says that it is missing
        st = path.stat()
        key = (st.st_ino, st.st_size, st.st_mtime_ns, str(recorded))
        if self._labels_checked == key:
            return
        if file_digest(path) != str(recorded):
            raise DamagedFileError(
                f"{path} is damaged or was changed: its contents do not match the digest {self.QUANTIZED} records "
                f"of the labels written with it; {self._quantize_again()}"
            )
        self._labels_checked = key

    def check_quantized_current(self) -> None:
        """StaleOutputError unless quantized.npz was made from the current volume.npz: it records that file's
        digest, or (a file written without one, by an older inkopt or a script) is not older than volume.npz.
        quantized.npz must be readable and its labels file the one it records (``io.DamagedFileError``
        otherwise). Nothing to check without quantized.npz; only those checks without volume.npz."""
        if not self.has_quantized():
            return
        arrays = self._quantized_arrays((VOLUME_DIGEST, LABELS_DIGEST, "labels_file"))
        self._check_labels(arrays)
        if not self.volume_path.is_file():
            return
        rec, again = arrays.get(VOLUME_DIGEST), self._quantize_again()
        if rec is None and self.volume_path.stat().st_mtime > self.quantized_path.stat().st_mtime:
            raise StaleOutputError(
                f"{self.quantized_path} is older than volume.npz and does not record which volume.npz it was "
                f"made from; {again}"
            )
        if rec is not None:
            self.check_volume_unchanged(
                str(rec),
                f"{self.quantized_path} was made from another volume.npz than the one in {self.path} (the run was "
                f"redone or continued after quantizing); {again}",
            )
