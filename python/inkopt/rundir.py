"""The run directory (docs/run-dir.md): the one owner of its files, their names, loading and checks.

Every optimisation (``inkopt slab``, ``inkopt optimize``) writes one folder; later stages (quantize, export,
evaluate) read it and add to it. All files are written atomically. Stages never build these paths themselves:
they ask a :class:`RunDir`.

``scene.npz`` is typed as a :class:`SceneRecord`: the sensor (texels), the targets, how the slab's faces map to
pictures, and the optimisation's constraints (``free_mask``, ``fixed_share``). Large objects store only
``free_mask``; :meth:`SceneRecord.fixed_share` rebuilds the dense shares from it and from the translucency
constraint (:class:`Translucency`, stored sparsely), so every reader sees the same constraints however the file
stores them.
"""
from __future__ import annotations

import json
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .io import load_npz, save_npz, write_json
from .model import FixedShares, InkTable, Texels, Volume
from .model.labelfile import LabelFileWriter

#: scene.npz stores the dense (z, y, x, N) fixed_share only below this many entries (else: free_mask only)
FIXED_SHARE_MAX_ENTRIES = 50_000_000


def white_fixed_share(free: np.ndarray, inks: InkTable) -> np.ndarray:
    """(z, y, x, N) float32 fixed ink shares: 100 % white where ``free`` (z, y, x) is False, none where True."""
    return white_fixed_shares(free, inks).dense()


def white_fixed_shares(free: np.ndarray, inks: InkTable) -> FixedShares:
    """:func:`white_fixed_share` in compact form (``free`` kept by reference)."""
    if "white" not in inks.names:
        raise ValueError(f"voxels that are not optimised (outside the object, the core below --shell-mm) are "
                         f"printed white, but the ink set {list(inks.names)} has no 'white'")
    held = np.zeros(len(inks), np.float32)
    held[inks.index("white")] = 1.0
    return FixedShares(free, held)


TRANSPARENT_INKS = ("transparent", "clear")  # ink names that count as the transparent ink


def transparent_ink(inks: InkTable) -> str:
    """The name of the ink set's transparent ink; one-line ValueError if it has none."""
    for name in TRANSPARENT_INKS:
        if name in inks.names:
            return name
    raise ValueError(f"--translucency needs a transparent ink ('transparent' or 'clear') in the ink set, but "
                     f"{list(inks.names)} has none; use e.g. --inks vero-cmykwt")


@dataclass
class Translucency:
    """A translucency constraint: the voxels ``index`` ((K,) int64, flat C-order indices of the (z, y, x) grid
    ``shape``) must hold the share ``share`` ((K,) float32 in (0, 1]) of ink ``ink`` (the transparent ink); the
    optimiser chooses the rest of their mixture. ``depth_mm``: how deep below the surface it reaches (None: the
    whole object); ``source``: the mask file or "alpha" (a mesh texture's alpha channel)."""

    ink: str
    shape: tuple
    index: np.ndarray
    share: np.ndarray
    depth_mm: float | None = None
    source: str = ""

    def __post_init__(self):
        self.shape = tuple(int(v) for v in self.shape)
        self.index = np.asarray(self.index, np.int64).reshape(-1)
        self.share = np.asarray(self.share, np.float32).reshape(-1)

    def grid(self) -> np.ndarray:
        """(z, y, x) float32: the required transparent share of every voxel (0: unconstrained)."""
        out = np.zeros(self.shape, np.float32)
        out.reshape(-1)[self.index] = self.share
        return out

    def texel_share(self, texels: Texels) -> np.ndarray:
        """(I,) float32: the required share at each texel's voxel."""
        return self.grid()[tuple(np.asarray(texels.voxel).T)]

    def apply(self, fixed: np.ndarray, inks: InkTable) -> np.ndarray:
        """Set the constrained voxels' transparent share in ``fixed`` (z, y, x, N) float32 (in place; returned).
        Their other fixed shares (the white of a core or outside voxel) shrink to make room: a voxel that was
        100 % white becomes ``share`` transparent + (1 - ``share``) white; free voxels keep no other fixed share.
        Idempotent."""
        self._check(fixed.shape, inks)
        flat = fixed.reshape(-1, len(inks))
        flat[self.index] = self._constrain(flat[self.index], inks)
        return fixed

    def applied(self, fixed: FixedShares, inks: InkTable) -> FixedShares:
        """:meth:`apply` on compact fixed shares: a new ``FixedShares`` whose dense form is ``apply``'s result."""
        self._check(fixed.shape, inks)
        index = np.union1d(fixed.index, self.index)
        rows = fixed.at(index)
        pos = np.searchsorted(index, self.index)
        rows[pos] = self._constrain(rows[pos], inks)
        return FixedShares(fixed.free, fixed.held, index, rows)

    def _check(self, shape, inks: InkTable) -> None:
        if tuple(shape[:3]) != self.shape:
            raise ValueError(f"translucency constraint is for a {self.shape} grid, not {tuple(shape[:3])}")
        if self.ink not in inks.names:
            raise ValueError(f"the translucency constraint needs ink '{self.ink}', not in {list(inks.names)}")

    def _constrain(self, rows: np.ndarray, inks: InkTable) -> np.ndarray:
        """The constrained voxels' fixed shares (K, N) float32 from their unconstrained ones (changed in place)."""
        t = inks.index(self.ink)
        rows[:, t] = 0.0
        other = rows.sum(1)
        room = 1.0 - self.share
        rows *= np.where(other > room, room / np.maximum(other, 1e-12), 1.0)[:, None]
        rows[:, t] = self.share
        return rows

    def arrays(self) -> dict:
        return {"translucency_ink": np.array(self.ink), "translucency_shape": np.array(self.shape, np.int64),
                "translucency_index": self.index, "translucency_share": self.share,
                "translucency_depth_mm": np.float64(np.nan if self.depth_mm is None else self.depth_mm),
                "translucency_source": np.array(self.source)}

    @classmethod
    def from_arrays(cls, d) -> "Translucency | None":
        if "translucency_index" not in d:
            return None
        depth = float(d["translucency_depth_mm"])
        return cls(str(d["translucency_ink"]), tuple(np.asarray(d["translucency_shape"])), d["translucency_index"],
                   d["translucency_share"], None if np.isnan(depth) else depth, str(d["translucency_source"]))


@dataclass
class MeshInfo:
    """Where a mesh run's object came from and how it sits on the grid (mm, x, y, z)."""

    mesh_path: str
    mesh_scale: float          # mm per model unit
    height_mm: float
    up: str
    origin_mm: np.ndarray      # (3,) low corner of voxel (0, 0, 0)
    voxel_mm: np.ndarray       # (3,)
    texel_closest_mm: np.ndarray  # (I, 3) closest surface point of each texel
    shell_mm: float | None

    def arrays(self) -> dict:
        return {"mesh_path": np.array(self.mesh_path), "mesh_scale": np.float64(self.mesh_scale),
                "height_mm": np.float64(self.height_mm), "up": np.array(self.up), "origin_mm": self.origin_mm,
                "voxel_mm": self.voxel_mm, "texel_closest_mm": self.texel_closest_mm,
                "shell_mm": np.float64(np.nan if self.shell_mm is None else self.shell_mm)}

    @classmethod
    def from_arrays(cls, d) -> "MeshInfo":
        shell = float(d["shell_mm"]) if "shell_mm" in d else float("nan")
        return cls(str(d["mesh_path"]), float(d["mesh_scale"]), float(d.get("height_mm", np.nan)),
                   str(d.get("up", "y")), np.asarray(d["origin_mm"]), np.asarray(d["voxel_mm"]),
                   np.asarray(d["texel_closest_mm"]), None if np.isnan(shell) else shell)


@dataclass
class SceneRecord:
    """The contents of scene.npz.

    kind: "slab" or "mesh"; texels: the sensor; target_rgb (I, 3) float32 linear; faces: the textured faces of a
    slab (e.g. ["bottom", "top"]) with pix[F] (H, W) int32 the texel index at each picture pixel (row 0 = top);
    free_mask (z, y, x) bool: the voxels the optimiser may change (None: decided by fixed_share alone);
    fixed_share_dense (z, y, x, N) float32 or None (includes the translucency); mesh: a mesh run's MeshInfo;
    translucency: the translucency constraint (:class:`Translucency`) or None.
    """

    kind: str
    texels: Texels
    target_rgb: np.ndarray
    faces: list[str] = field(default_factory=list)
    pix: dict[str, np.ndarray] = field(default_factory=dict)
    free_mask: np.ndarray | None = None
    fixed_share_dense: np.ndarray | None = None
    mesh: MeshInfo | None = None
    translucency: Translucency | None = None

    def __post_init__(self):
        self.target_rgb = np.asarray(self.target_rgb, np.float32)
        if self.target_rgb.shape != (len(self.texels), 3) or len(self.texels) == 0:
            raise ValueError(f"scene target_rgb has shape {self.target_rgb.shape}, expected ({len(self.texels)}, 3)"
                             " with texels")

    def fixed_share(self, inks: InkTable, shape=None) -> np.ndarray | None:
        """(z, y, x, N) float32 fixed ink shares: stored densely, or rebuilt from ``free_mask`` (100 % white
        wherever the mask is False) and the translucency constraint, or None if the scene has no constraints.
        ``shape`` (z, y, x) checks it."""
        tr = self.translucency
        if self.fixed_share_dense is not None:
            fixed = np.asarray(self.fixed_share_dense, np.float32)
        elif self.free_mask is not None:
            fixed = white_fixed_share(np.asarray(self.free_mask, bool), inks)
        elif tr is not None:
            fixed = np.zeros(tr.shape + (len(inks),), np.float32)
        else:
            return None
        if tr is not None and self.fixed_share_dense is None:
            tr.apply(fixed, inks)
        if fixed.shape[-1] != len(inks) or (shape is not None and fixed.shape[:3] != tuple(shape)):
            raise ValueError(f"scene fixed_share has shape {fixed.shape}, expected {tuple(shape or ())} x "
                             f"{len(inks)} inks")
        return fixed

    def arrays(self) -> dict:
        out = {**self.texels.to_arrays(), "target_rgb": self.target_rgb, "kind": np.array(self.kind)}
        if self.faces:
            out["faces"] = np.array(self.faces)
        out.update({f"pix_{f}": p for f, p in self.pix.items()})
        if self.free_mask is not None:
            out["free_mask"] = self.free_mask
        if self.fixed_share_dense is not None and self.fixed_share_dense.size < FIXED_SHARE_MAX_ENTRIES:
            out["fixed_share"] = self.fixed_share_dense
        if self.mesh is not None:
            out.update(self.mesh.arrays())
        if self.translucency is not None:
            out.update(self.translucency.arrays())
        return out

    @classmethod
    def from_arrays(cls, d, where: str = "scene.npz") -> "SceneRecord":
        for k in ("texel_voxel", "texel_face", "texel_normal", "target_rgb"):
            if k not in d:
                raise ValueError(f"{where} lacks array '{k}'")
        faces = [str(f) for f in np.asarray(d["faces"]).reshape(-1)] if "faces" in d else []
        kind = str(d.get("kind", "slab"))
        return cls(kind, Texels.from_arrays(d), d["target_rgb"], faces,
                   {f: np.asarray(d[f"pix_{f}"]) for f in faces if f"pix_{f}" in d},
                   np.asarray(d["free_mask"], bool) if "free_mask" in d else None,
                   d.get("fixed_share"), MeshInfo.from_arrays(d) if kind == "mesh" and "mesh_path" in d else None,
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
