"""The voxel volume model, its texels, and the documented ``.npz`` volume file.

Conventions (docs/conventions.md): arrays are (z, y, x[, c]); ``voxel_mm`` and normals are (x, y, z);
coefficients in mm^-1; z = 0 is the bottom layer.

A volume file (``.npz``) holds one of three medium forms:

- dense:    ``sigma_s``, ``sigma_a``  float32 (z, y, x, 3), mm^-1
- mixture:  ``mixture`` float32 (z, y, x, N), rows summing to 1, plus the ink table
- labels:   ``labels`` uint8 (z, y, x), ink index per voxel (255 = empty), plus the ink table

ink table: ``ink_names`` (N,) str, ``ink_sigma_s``/``ink_sigma_a`` float32 (N, 3) mm^-1.
Always: ``voxel_mm`` (3,) float (x, y, z). Optional: ``g`` (default 0.4), ``ior`` (default 1.5),
``inside`` bool (z, y, x) (default: the whole box), ``normals`` float32 (z, y, x, 3) outward shading normals
(x, y, z components) for surface voxels, ``boundary`` ("box" or "periodic-xy").
"""
from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .materials import DEFAULT_G, InkTable, mix

BOUNDARIES = ("box", "periodic-xy")
FACE_NAMES = ("-x", "+x", "-y", "+y", "-z", "+z")
FACE_ALIASES = {"left": 0, "right": 1, "front": 2, "back": 3, "bottom": 4, "top": 5}
# Outward normal (x, y, z) of each face id.
FACE_NORMALS = np.array([[-1, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0], [0, 0, -1], [0, 0, 1]], np.float32)
# Memory the renderer may use for one volume; a volume above this is refused (bytes).
MAX_VOLUME_BYTES = int(os.environ.get("INKOPT_MAX_VOLUME_BYTES", 16 * 2**30))
EMPTY = 255


def face_id(name: str | int) -> int:
    if isinstance(name, (int, np.integer)) and 0 <= int(name) < 6:
        return int(name)
    key = str(name).strip().lower()
    if key in FACE_ALIASES:
        return FACE_ALIASES[key]
    if key in FACE_NAMES:
        return FACE_NAMES.index(key)
    raise ValueError(f"unknown face '{name}'; use one of {list(FACE_ALIASES)} or {list(FACE_NAMES)}")


class VolumeError(ValueError):
    """A volume that cannot be rendered; the message is one line naming the problem."""


@dataclass
class Volume:
    """A voxel medium. Exactly one of (sigma_s and sigma_a), mixture, labels is set."""

    voxel_mm: np.ndarray
    sigma_s: np.ndarray | None = None
    sigma_a: np.ndarray | None = None
    mixture: np.ndarray | None = None
    labels: np.ndarray | None = None
    inks: InkTable | None = None
    g: float = DEFAULT_G
    ior: float = 1.5
    inside: np.ndarray | None = None
    normals: np.ndarray | None = None
    boundary: str = "box"
    extra: dict = field(default_factory=dict)

    def __post_init__(self):
        self.voxel_mm = np.asarray(self.voxel_mm, dtype=np.float64).reshape(-1)
        self.validate()

    # ----------------------------------------------------------------- validation
    @property
    def form(self) -> str:
        return "dense" if self.sigma_s is not None else "mixture" if self.mixture is not None else "labels"

    @property
    def shape(self) -> tuple[int, int, int]:
        arr = self.sigma_s if self.sigma_s is not None else self.mixture if self.mixture is not None else self.labels
        return tuple(int(s) for s in arr.shape[:3])

    def validate(self) -> None:
        forms = [self.sigma_s is not None or self.sigma_a is not None, self.mixture is not None,
                 self.labels is not None]
        if sum(forms) != 1:
            raise VolumeError("volume needs exactly one of: sigma_s+sigma_a, mixture, labels")
        if self.voxel_mm.shape != (3,) or not np.all(np.isfinite(self.voxel_mm)) or np.any(self.voxel_mm <= 0):
            raise VolumeError(f"voxel_mm must be 3 positive finite sizes (x, y, z) in mm, got {self.voxel_mm}")
        if self.boundary not in BOUNDARIES:
            raise VolumeError(f"unknown boundary '{self.boundary}'; use one of {list(BOUNDARIES)}")
        if not -1 < self.g < 1:
            raise VolumeError(f"g must lie in (-1, 1), got {self.g}")
        if not (np.isfinite(self.ior) and self.ior > 0):
            raise VolumeError(f"ior must be positive, got {self.ior}")
        if self.form == "dense":
            if self.sigma_s is None or self.sigma_a is None:
                raise VolumeError("dense volume needs both sigma_s and sigma_a")
            for key in ("sigma_s", "sigma_a"):
                arr = np.ascontiguousarray(getattr(self, key), dtype=np.float32)
                if arr.ndim != 4 or arr.shape[3] != 3:
                    raise VolumeError(f"{key} must have shape (z, y, x, 3), got {arr.shape}")
                if not np.all(np.isfinite(arr)):
                    raise VolumeError(f"{key} contains NaN or infinite values")
                if np.any(arr < 0):
                    raise VolumeError(f"{key} contains negative coefficients")
                setattr(self, key, arr)
            if self.sigma_s.shape != self.sigma_a.shape:
                raise VolumeError(f"sigma_s {self.sigma_s.shape} and sigma_a {self.sigma_a.shape} differ in shape")
        else:
            if self.inks is None:
                raise VolumeError(f"a {self.form} volume needs an ink table (ink_names, ink_sigma_s, ink_sigma_a)")
            if self.form == "mixture":
                m = np.ascontiguousarray(self.mixture, dtype=np.float32)
                if m.ndim != 4 or m.shape[3] != len(self.inks):
                    raise VolumeError(f"mixture must have shape (z, y, x, {len(self.inks)}), got {m.shape}")
                if not np.all(np.isfinite(m)) or np.any(m < 0):
                    raise VolumeError("mixture must be finite and non-negative")
                self.mixture = m
            else:
                lab = np.ascontiguousarray(self.labels)
                if lab.dtype != np.uint8 or lab.ndim != 3:
                    raise VolumeError(f"labels must be uint8 (z, y, x), got {lab.dtype} {lab.shape}")
                used = lab[lab != EMPTY]
                if used.size and int(used.max()) >= len(self.inks):
                    raise VolumeError(f"labels use ink {int(used.max())} but the ink table has {len(self.inks)}")
                self.labels = lab
        shp = self.shape
        if min(shp) < 1:
            raise VolumeError(f"volume shape {shp} is empty")
        if self.inside is not None:
            ins = np.asarray(self.inside)
            if ins.shape != shp:
                raise VolumeError(f"inside mask shape {ins.shape} differs from volume shape {shp}")
            self.inside = np.ascontiguousarray(ins, dtype=bool)
        if self.normals is not None:
            nrm = np.ascontiguousarray(self.normals, dtype=np.float32)
            if nrm.shape != shp + (3,):
                raise VolumeError(f"normals must have shape {shp + (3,)}, got {nrm.shape}")
            self.normals = nrm
        need = self.render_bytes()
        if need > MAX_VOLUME_BYTES:
            raise VolumeError(f"volume {shp} needs {need / 2**30:.1f} GiB to render, more than the "
                              f"{MAX_VOLUME_BYTES / 2**30:.1f} GiB allowed (INKOPT_MAX_VOLUME_BYTES)")

    def render_bytes(self) -> int:
        """Memory the renderer needs for this medium (bytes)."""
        n = int(np.prod(self.shape, dtype=np.int64))
        per = 1 if self.form == "labels" else 24  # labels: u8; else sigma_s, sigma_a f32 x 3 channels
        per += 1 if self.inside is not None else 0
        per += 12 if self.normals is not None else 0
        return n * per

    # ----------------------------------------------------------------- conversions
    def coefficients(self) -> tuple[np.ndarray, np.ndarray]:
        """(sigma_s, sigma_a), each (z, y, x, 3) float32 mm^-1, of a dense or mixture volume."""
        if self.form == "dense":
            return self.sigma_s, self.sigma_a
        if self.form == "mixture":
            return mix(self.mixture, self.inks)
        s = np.zeros(self.shape + (3,), np.float32)
        a = np.zeros_like(s)
        for k in range(len(self.inks)):
            sel = self.labels == k
            s[sel] = self.inks.sigma_s[k]
            a[sel] = self.inks.sigma_a[k]
        return s, a

    def inside_mask(self) -> np.ndarray:
        if self.inside is not None:
            return self.inside
        if self.form == "labels":
            return self.labels != EMPTY
        return np.ones(self.shape, bool)

    def with_mixture(self, mixture: np.ndarray) -> "Volume":
        return replace(self, sigma_s=None, sigma_a=None, labels=None, mixture=mixture)

    # ----------------------------------------------------------------- files
    def to_arrays(self) -> dict:
        out = {"voxel_mm": self.voxel_mm, "g": np.float64(self.g), "ior": np.float64(self.ior),
               "boundary": np.array(self.boundary)}
        if self.form == "dense":
            out.update(sigma_s=self.sigma_s, sigma_a=self.sigma_a)
        elif self.form == "mixture":
            out["mixture"] = self.mixture
        else:
            out["labels"] = self.labels
        if self.inks is not None:
            out.update(self.inks.to_arrays())
        if self.inside is not None:
            out["inside"] = self.inside
        if self.normals is not None:
            out["normals"] = self.normals
        out.update(self.extra)
        return out

    def save(self, path: str | Path) -> None:
        save_npz(path, self.to_arrays())

    @classmethod
    def load(cls, path: str | Path) -> "Volume":
        path = Path(path)
        if not path.is_file():
            raise VolumeError(f"volume file {path} does not exist")
        try:
            data = dict(np.load(path, allow_pickle=False))
        except Exception as exc:  # zipfile/format errors: one line
            raise VolumeError(f"{path} is not a readable .npz volume file ({type(exc).__name__}: {exc})") from None
        if "voxel_mm" not in data:
            raise VolumeError(f"{path}: missing array 'voxel_mm' (3 voxel sizes x, y, z in mm)")
        known = {"sigma_s", "sigma_a", "mixture", "labels", "ink_names", "ink_sigma_s", "ink_sigma_a", "voxel_mm",
                 "g", "ior", "inside", "normals", "boundary"}
        g = float(data["g"]) if "g" in data else DEFAULT_G
        inks = None
        if "ink_names" in data:
            try:
                inks = InkTable.from_arrays(data, g)
            except (KeyError, ValueError) as exc:
                raise VolumeError(f"{path}: bad ink table: {exc}") from None
        return cls(voxel_mm=data["voxel_mm"], sigma_s=data.get("sigma_s"), sigma_a=data.get("sigma_a"),
                   mixture=data.get("mixture"), labels=data.get("labels"), inks=inks, g=g,
                   ior=float(data["ior"]) if "ior" in data else 1.5, inside=data.get("inside"),
                   normals=data.get("normals"),
                   boundary=str(data["boundary"]) if "boundary" in data else "box",
                   extra={k: v for k, v in data.items() if k not in known})


@dataclass
class Texels:
    """Surface texels: the sensor elements of the renderer (docs/conventions.md, "Faces and texels").

    voxel  (I, 3) int32   voxel index (z, y, x) the texel belongs to
    face   (I,)   uint8   face id its camera rays cross (0 -x, 1 +x, 2 -y, 3 +y, 4 -z, 5 +z)
    normal (I, 3) float32 outward unit shading normal (x, y, z)
    """

    voxel: np.ndarray
    face: np.ndarray
    normal: np.ndarray
    #: True for mesh texels (one per surface voxel): positions are voxel centres, not face centres.
    centred: bool = False

    def __post_init__(self):
        self.voxel = np.ascontiguousarray(self.voxel, dtype=np.int32).reshape(-1, 3)
        self.face = np.ascontiguousarray(self.face, dtype=np.uint8).reshape(-1)
        self.normal = np.ascontiguousarray(self.normal, dtype=np.float32).reshape(-1, 3)
        if not (len(self.voxel) == len(self.face) == len(self.normal)):
            raise ValueError("texel arrays voxel, face, normal differ in length")

    def __len__(self) -> int:
        return len(self.face)

    @property
    def pos_vox(self) -> np.ndarray:
        """(I, 3) float64 positions (x, y, z) in voxel units: face centres (box texels), or voxel centres
        (mesh texels, ``centred``); neighbouring texels of one face or surface are 1 apart."""
        centre = self.voxel[:, ::-1].astype(np.float64) + 0.5
        if self.centred:
            return centre
        return centre + 0.5 * FACE_NORMALS[self.face].astype(np.float64)

    def position_mm(self, voxel_mm) -> np.ndarray:
        return self.pos_vox * np.asarray(voxel_mm, np.float64)

    def subset(self, sel) -> "Texels":
        return Texels(self.voxel[sel], self.face[sel], self.normal[sel], self.centred)

    @classmethod
    def box_faces(cls, shape, faces=None) -> "Texels":
        """Texels of the faces of a box volume of ``shape`` (z, y, x), in face-id order (all 6 by default)."""
        nz, ny, nx = shape
        faces = range(6) if faces is None else sorted({face_id(f) for f in faces})
        vox, fid = [], []
        for f in faces:
            axis = 2 - f // 2  # array axis of the face normal: x -> 2, y -> 1, z -> 0
            idx = np.stack(np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij"), -1)
            sl = [slice(None)] * 3
            sl[axis] = shape[axis] - 1 if f % 2 else 0
            v = idx[tuple(sl)].reshape(-1, 3)
            vox.append(v)
            fid.append(np.full(len(v), f, np.uint8))
        vox = np.concatenate(vox) if vox else np.zeros((0, 3), np.int32)
        fid = np.concatenate(fid) if fid else np.zeros(0, np.uint8)
        return cls(vox, fid, FACE_NORMALS[fid])

    @classmethod
    def exposed_faces(cls, inside: np.ndarray, faces=None) -> "Texels":
        """Every exposed face of an arbitrary ``inside`` mask (a face whose neighbour is outside or off-grid)."""
        pad = np.pad(inside, 1, constant_values=False)
        vox, fid = [], []
        for f in (range(6) if faces is None else sorted({face_id(x) for x in faces})):
            axis = 2 - f // 2
            step = 1 if f % 2 else -1
            nb = np.roll(pad, -step, axis=axis)[1:-1, 1:-1, 1:-1]
            v = np.argwhere(inside & ~nb)
            vox.append(v)
            fid.append(np.full(len(v), f, np.uint8))
        fid = np.concatenate(fid)
        return cls(np.concatenate(vox), fid, FACE_NORMALS[fid])

    @classmethod
    def from_normals(cls, inside: np.ndarray, normals: np.ndarray) -> "Texels":
        """Mesh texels: one per surface voxel (an inside voxel with an outside 6-neighbour), in C order of
        (z, y, x); ``normal`` = the voxel's shading normal from ``normals`` (z, y, x, 3), and ``face`` = its
        exposed face most aligned with that normal."""
        faces = cls.exposed_faces(inside)
        nrm = normals[tuple(faces.voxel.T)].astype(np.float64)
        length = np.linalg.norm(nrm, axis=1)
        nrm = np.where(length[:, None] > 1e-6, nrm / np.maximum(length, 1e-12)[:, None], FACE_NORMALS[faces.face])
        align = np.einsum("ij,ij->i", nrm, FACE_NORMALS[faces.face])
        flat = np.ravel_multi_index(tuple(faces.voxel.T), inside.shape)
        # Per voxel keep the exposed face with the largest alignment: sort by (voxel, -alignment).
        order = np.lexsort((-align, flat))
        first = np.ones(len(order), bool)
        first[1:] = flat[order][1:] != flat[order][:-1]
        keep = order[first]
        keep = keep[np.argsort(flat[keep], kind="stable")]
        n_keep = nrm[keep]
        bad = np.einsum("ij,ij->i", n_keep, FACE_NORMALS[faces.face[keep]]) <= 0.05
        n_keep[bad] = FACE_NORMALS[faces.face[keep][bad]]  # a normal facing away from every exposed face
        return cls(faces.voxel[keep], faces.face[keep], n_keep, centred=True)

    @classmethod
    def for_volume(cls, volume: "Volume", faces=None) -> "Texels":
        """The default sensor of a volume: its exposed faces (periodic-xy: only -z and +z), or for a volume with
        shading normals (a voxelized mesh) one texel per surface voxel. ``faces`` restricts to some faces."""
        if volume.normals is not None and faces is None:
            return cls.from_normals(volume.inside_mask(), volume.normals)
        if volume.boundary == "periodic-xy":
            allowed = {4, 5}
            faces = allowed if faces is None else {face_id(f) for f in faces} & allowed
            if not faces:
                raise ValueError("a periodic-xy volume has only the top and bottom faces")
        if volume.inside is None and volume.form != "labels":
            return cls.box_faces(volume.shape, faces)
        return cls.exposed_faces(volume.inside_mask(), faces)

    def to_arrays(self) -> dict:
        return {"texel_voxel": self.voxel, "texel_face": self.face, "texel_normal": self.normal,
                "texel_centred": np.bool_(self.centred)}

    @classmethod
    def from_arrays(cls, data) -> "Texels":
        return cls(data["texel_voxel"], data["texel_face"], data["texel_normal"],
                   bool(data["texel_centred"]) if "texel_centred" in data else False)


def save_npz(path: str | Path, arrays: dict, compressed: bool = True) -> None:
    """Write an .npz atomically (temporary file in the same folder, then rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp.npz", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            (np.savez_compressed if compressed else np.savez)(fh, **arrays)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
