"""The run directory (docs/run-dir.md): the one owner of its files, their names, loading and checks.

Every optimisation (``inkopt slab``, ``inkopt optimize``) writes one folder; later stages (quantize, export,
evaluate) read it and add to it. All files are written atomically. Stages never build these paths themselves:
they ask a :class:`RunDir`.

``scene.npz`` is typed as a :class:`SceneRecord`: the sensor (texels), the targets, how the slab's faces map to
pictures, and the optimisation's constraints (``free_mask``, ``fixed_share``). Large objects store only
``free_mask``; :meth:`SceneRecord.fixed_share` rebuilds the fixed shares from it and from the translucency
constraint (``model.Translucency``, stored sparsely), so every reader sees the same constraints however the file
stores them.
"""
from __future__ import annotations

import json
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .io import load_npz, save_npz, write_json
from .model import FixedShares, InkTable, MeshInfo, Texels, Translucency, Volume, scene_fixed_shares
from .model.labelfile import LabelFileWriter

#: scene.npz stores the dense (z, y, x, N) fixed_share only below this many entries (else: free_mask only)
FIXED_SHARE_MAX_ENTRIES = 50_000_000


@dataclass
class SceneRecord:
    """The contents of scene.npz.

    kind: "slab" or "mesh"; texels: the sensor; target_rgb (I, 3) float32 linear; faces: the textured faces of a
    slab (e.g. ["bottom", "top"]) with pix[F] (H, W) int32 the texel index at each picture pixel (row 0 = top);
    free_mask (z, y, x) bool: the voxels the optimiser may change (None: decided by the fixed shares alone);
    fixed: the fixed ink shares (``FixedShares``, translucency included) or None (then rebuilt from free_mask and
    translucency); mesh: a mesh run's ``MeshInfo``; translucency: the translucency constraint (``Translucency``)
    or None.
    """

    kind: str
    texels: Texels
    target_rgb: np.ndarray
    faces: list[str] = field(default_factory=list)
    pix: dict[str, np.ndarray] = field(default_factory=dict)
    free_mask: np.ndarray | None = None
    fixed: FixedShares | None = None
    mesh: MeshInfo | None = None
    translucency: Translucency | None = None

    def __post_init__(self):
        self.target_rgb = np.asarray(self.target_rgb, np.float32)
        if self.target_rgb.shape != (len(self.texels), 3) or len(self.texels) == 0:
            raise ValueError(f"scene target_rgb has shape {self.target_rgb.shape}, expected ({len(self.texels)}, 3)"
                             " with texels")

    def fixed_share(self, inks: InkTable, shape=None) -> FixedShares | None:
        """The (z, y, x, N) fixed ink shares: as stored, or rebuilt from ``free_mask`` (100 % white wherever the
        mask is False) and the translucency constraint (``model.scene_fixed_shares``), or None if the scene has
        no constraints. ``shape`` (z, y, x) checks it."""
        fixed = self.fixed
        if fixed is None:
            free = None if self.free_mask is None else np.asarray(self.free_mask, bool)
            fixed = scene_fixed_shares(inks, free, self.translucency)
        if fixed is not None and (fixed.shape[-1] != len(inks) or (shape is not None
                                                                   and fixed.shape[:3] != tuple(shape))):
            raise ValueError(f"scene fixed_share has shape {fixed.shape}, expected {tuple(shape or ())} x "
                             f"{len(inks)} inks")
        return fixed

    def arrays(self) -> dict:
        """The arrays of scene.npz (the dense fixed shares only below ``FIXED_SHARE_MAX_ENTRIES`` entries)."""
        out = {**self.texels.to_arrays(), "target_rgb": self.target_rgb, "kind": np.array(self.kind)}
        if self.faces:
            out["faces"] = np.array(self.faces)
        out.update({f"pix_{f}": p for f, p in self.pix.items()})
        if self.free_mask is not None:
            out["free_mask"] = self.free_mask
        if self.fixed is not None and np.prod(self.fixed.shape) < FIXED_SHARE_MAX_ENTRIES:
            out["fixed_share"] = self.fixed.dense()
        if self.mesh is not None:
            out.update(self.mesh.arrays())
        if self.translucency is not None:
            out.update(self.translucency.arrays())
        return out

    @classmethod
    def from_arrays(cls, d, where: str = "scene.npz") -> SceneRecord:
        for k in ("texel_voxel", "texel_face", "texel_normal", "target_rgb", "kind"):
            if k not in d:
                raise ValueError(f"{where} lacks array '{k}'")
        faces = [str(f) for f in np.asarray(d["faces"]).reshape(-1)] if "faces" in d else []
        kind = str(d["kind"])
        return cls(kind, Texels.from_arrays(d), d["target_rgb"], faces,
                   {f: np.asarray(d[f"pix_{f}"]) for f in faces if f"pix_{f}" in d},
                   np.asarray(d["free_mask"], bool) if "free_mask" in d else None,
                   FixedShares.from_dense(d["fixed_share"]) if "fixed_share" in d else None,
                   MeshInfo.from_arrays(d) if kind == "mesh" and "mesh_path" in d else None,
                   Translucency.from_arrays(d))


class RunDir:
    """A run directory. ``RunDir(path)`` requires it to exist; ``RunDir.create(path)`` makes it."""

    VOLUME, SCENE, CHECKPOINT, REPORT = "volume.npz", "scene.npz", "checkpoint.npz", "report.json"
    QUANTIZED, EVALUATION, SLICES, LOSS_PNG = "quantized.npz", "evaluation.json", "slices", "loss.png"
    QUANTIZED_LABELS = "quantized_labels.npy"

    def __init__(self, path):
        self.path = Path(path)
        if not self.path.is_dir():
            raise ValueError(f"run directory {self.path} does not exist")

    @classmethod
    def create(cls, path) -> "RunDir":
        """Make the folder (if needed) and remove the temporary files of an earlier process that was killed while
        writing (``inkopt.io`` writes ``NAME.XXXX.tmp[.npz]`` and renames it into place)."""
        Path(path).mkdir(parents=True, exist_ok=True)
        for stale in [*Path(path).glob("*.tmp"), *Path(path).glob("*.tmp.npz")]:
            stale.unlink(missing_ok=True)
        return cls(path)

    def __truediv__(self, name: str) -> Path:
        return self.path / name

    def __str__(self) -> str:
        return str(self.path)

    @property
    def checkpoint(self) -> Path:
        return self.path / self.CHECKPOINT

    def _need(self, name: str, hint: str) -> Path:
        p = self.path / name
        if not p.is_file():
            raise ValueError(f"{p} does not exist ({hint})")
        return p

    # ------------------------------------------------------------------ the continuous result
    def save_volume(self, vol: Volume) -> Path:
        vol.save(self.path / self.VOLUME)
        return self.path / self.VOLUME

    def save_volume_slabs(self, geometry: Volume, mixture_slabs, inks) -> Path:
        """volume.npz of ``geometry`` with a mixture given as z slabs (``Volume.save_with_mixture``)."""
        geometry.save_with_mixture(self.path / self.VOLUME, mixture_slabs, inks)
        return self.path / self.VOLUME

    def load_volume(self) -> Volume:
        """The optimised mixture volume (volume.npz)."""
        p = self._need(self.VOLUME, "run 'inkopt slab' or 'inkopt optimize' first")
        vol = Volume.load(p)
        if vol.form != "mixture":
            raise ValueError(f"{p} holds a {vol.form} volume; this step needs a mixture volume")
        return vol

    # ------------------------------------------------------------------ the scene
    def save_scene(self, rec: SceneRecord) -> Path:
        save_npz(self.path / self.SCENE, rec.arrays())
        return self.path / self.SCENE

    def load_scene(self) -> SceneRecord:
        p = self._need(self.SCENE, "run 'inkopt slab' or 'inkopt optimize' first")
        return SceneRecord.from_arrays(load_npz(p, "scene file"), str(p))

    # ------------------------------------------------------------------ printer labels
    def save_quantized(self, vol: Volume) -> Path:
        """quantized.npz (everything but the labels) + quantized_labels.npy (the labels, copied layer by layer)."""
        with self.quantized_writer(vol, vol.shape) as w:
            for k in range(vol.shape[0]):
                w[k] = vol.labels[k]
        return self.path / self.QUANTIZED

    @contextmanager
    def quantized_writer(self, meta: Volume, shape, normals=None):
        """Write the quantized volume one printer layer at a time: ``with d.quantized_writer(meta, shape) as w:
        w[k] = layer`` (k = 0, 1, ...; ``model.labelfile.LabelFileWriter``). ``meta``: a labels Volume giving
        everything but the labels (voxel size, inks, settings; its own labels are ignored); ``normals``: the
        printer grid's ``SurfaceNormals`` or None. On success
        the labels file replaces quantized_labels.npy and then quantized.npz is written (the old quantized.npz is
        removed first, so a crash never pairs an old quantized.npz with new labels)."""
        arrays = {k: v for k, v in meta.to_arrays().items() if k != "labels"}
        if normals is not None:
            arrays.update(normal_index=normals.index, normal_vectors=normals.vectors)
        w = LabelFileWriter(self.path / self.QUANTIZED_LABELS, shape)
        try:
            yield w
            (self.path / self.QUANTIZED).unlink(missing_ok=True)
            w.commit()
        except BaseException:
            w.abort()
            raise
        save_npz(self.path / self.QUANTIZED, {**arrays, "labels_file": np.array(self.QUANTIZED_LABELS),
                                              "labels_shape": np.asarray(w.shape, np.int64),
                                              "label_counts": w.counts})

    def volume_file(self) -> Path:
        """The path of volume.npz (checked to exist), for stages that read it lazily."""
        return self._need(self.VOLUME, "run 'inkopt slab' or 'inkopt optimize' first")

    def has_quantized(self) -> bool:
        return (self.path / self.QUANTIZED).is_file()

    def load_quantized(self) -> Volume:
        p = self._need(self.QUANTIZED, f"run 'inkopt quantize {self.path}' first")
        vol = Volume.load(p)
        if vol.form != "labels":
            raise ValueError(f"{p} holds a {vol.form} volume, not printer labels")
        return vol

    # ------------------------------------------------------------------ reports
    def write_report(self, report: dict) -> Path:
        return write_json(self.path / self.REPORT, report)

    def read_report(self) -> dict:
        return json.loads(self._need(self.REPORT, "the run has not finished").read_text())

    def write_evaluation(self, ev: dict) -> Path:
        return write_json(self.path / self.EVALUATION, ev, indent=1)

    def slices(self) -> Path:
        return self.path / self.SLICES
