"""Surface texels: the renderer's sensor elements (docs/conventions.md, "Faces and texels").

A texel is one exposed voxel face (boxes, slabs) or one surface voxel with its shading normal (voxelized
meshes). Texel order is part of every per-texel array (targets, predictions, adjoints): box faces in face-id
order, each in C order of (z, y, x); mesh texels in C order of their voxels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .normals import SurfaceNormals

FACE_NAMES = ("-x", "+x", "-y", "+y", "-z", "+z")
FACE_ALIASES = {"left": 0, "right": 1, "front": 2, "back": 3, "bottom": 4, "top": 5}
# Outward normal (x, y, z) of each face id.
FACE_NORMALS = np.array([[-1, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0], [0, 0, -1], [0, 0, 1]], np.float32)


def face_id(name: str | int) -> int:
    if isinstance(name, (int, np.integer)) and 0 <= int(name) < 6:
        return int(name)
    key = str(name).strip().lower()
    if key in FACE_ALIASES:
        return FACE_ALIASES[key]
    if key in FACE_NAMES:
        return FACE_NAMES.index(key)
    raise ValueError(f"unknown face '{name}'; use one of {list(FACE_ALIASES)} or {list(FACE_NAMES)}")


#: z layers of a mask searched at a time for exposed faces (``Texels.exposed_faces``)
EXPOSED_SLAB = 32


def _neighbours(inside: np.ndarray, f: int, z0: int, z1: int) -> np.ndarray:
    """(z1 - z0, y, x) bool: for each voxel of layers z0:z1 of ``inside``, whether its neighbour across face ``f``
    is inside (False off the grid)."""
    axis, step = 2 - f // 2, 1 if f % 2 else -1
    out = np.zeros((z1 - z0, *inside.shape[1:]), bool)
    if axis == 0:
        lo, hi = max(z0 + step, 0), min(z1 + step, inside.shape[0])
        out[lo - z0 - step : hi - z0 - step] = inside[lo:hi]
        return out
    src, dst = [slice(None)] * 3, [slice(None)] * 3
    src[axis], dst[axis] = (slice(1, None), slice(0, -1)) if step == 1 else (slice(0, -1), slice(1, None))
    out[tuple(dst)] = inside[z0:z1][tuple(src)]
    return out


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

    def subset(self, sel) -> Texels:
        return Texels(self.voxel[sel], self.face[sel], self.normal[sel], self.centred)

    @classmethod
    def box_faces(cls, shape, faces=None) -> Texels:
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
    def exposed_faces(cls, inside, faces=None) -> Texels:
        """Every exposed face of an arbitrary ``inside`` mask (a face whose neighbour is outside or off-grid), face by
        face, each in C order of (z, y, x); found ``EXPOSED_SLAB`` z layers at a time, each slab read once with a
        plane either side (a few bytes per voxel of a slab, not of the grid). ``inside``: a (z, y, x) bool array,
        or a mask read by slices of z-planes (``PackedMask``, ``media.NonEmpty``), never made whole."""
        if isinstance(inside, np.ndarray) or not hasattr(inside, "shape"):
            inside = np.asarray(inside, bool)
        nz = inside.shape[0]
        fids = list(range(6)) if faces is None else sorted({face_id(x) for x in faces})
        vox: dict[int, list] = {f: [] for f in fids}
        for z0 in range(0, nz, EXPOSED_SLAB):
            z1 = min(nz, z0 + EXPOSED_SLAB)
            lo, hi = max(z0 - 1, 0), min(z1 + 1, nz)
            block = np.asarray(inside[lo:hi], bool)  # beyond the block is beyond the grid
            for f in fids:
                v = np.argwhere(block[z0 - lo : z1 - lo] & ~_neighbours(block, f, z0 - lo, z1 - lo))
                v[:, 0] += z0
                vox[f].append(v)
        fid = np.concatenate([np.full(sum(len(v) for v in vox[f]), f, np.uint8) for f in fids])
        voxels = np.concatenate([v for f in fids for v in vox[f]]) if fids else np.empty((0, 3), np.int64)
        return cls(voxels, fid, FACE_NORMALS[fid])

    @classmethod
    def from_normals(cls, inside, normals) -> Texels:
        """Mesh texels: one per surface voxel (an inside voxel with an outside 6-neighbour), in C order of
        (z, y, x); ``normal`` = the voxel's shading normal from ``normals`` (``SurfaceNormals``, or a dense
        (z, y, x, 3) array), and ``face`` = its exposed face most aligned with that normal. ``inside``: as
        ``exposed_faces`` takes it."""
        if not isinstance(normals, SurfaceNormals):  # a dense (z, y, x, 3) array
            normals = SurfaceNormals.from_dense(normals)
        faces = cls.exposed_faces(inside)
        nrm = normals.at(faces.voxel).astype(np.float64)
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
    def for_volume(cls, volume, faces=None) -> Texels:
        """The default sensor of a volume: its exposed faces (periodic-xy: only -z and +z), or for a volume with
        shading normals (a voxelized mesh) one texel per surface voxel. ``faces`` restricts to some faces."""
        planes = volume.inside_planes()  # read a slab at a time: no grid-sized mask
        if volume.normals is not None and faces is None:
            return cls.from_normals(volume.inside_mask() if planes is None else planes, volume.normals)
        if volume.boundary == "periodic-xy":
            allowed = {4, 5}
            faces = allowed if faces is None else {face_id(f) for f in faces} & allowed
            if not faces:
                raise ValueError("a periodic-xy volume has only the top and bottom faces")
        if volume.inside is None and volume.form != "labels":
            return cls.box_faces(volume.shape, faces)
        return cls.exposed_faces(volume.inside_mask() if planes is None else planes, faces)

    def to_arrays(self) -> dict:
        return {
            "texel_voxel": self.voxel,
            "texel_face": self.face,
            "texel_normal": self.normal,
            "texel_centred": np.bool_(self.centred),
        }

    @classmethod
    def from_arrays(cls, data) -> Texels:
        """The texels of a file's arrays; other than integer voxel indices, face ids 0..5 and finite normals is a
        ValueError."""
        voxel, face, normal = (np.asarray(data[k]) for k in ("texel_voxel", "texel_face", "texel_normal"))
        with np.errstate(over="ignore", invalid="ignore"):
            normal = normal.astype(np.float32) if normal.dtype.kind in "fiu" else normal
        if (
            voxel.dtype.kind not in "iu"
            or face.dtype.kind not in "iu"
            or not np.all((voxel >= 0) & (voxel < 2**31))
            or not np.all((face >= 0) & (face <= 5))
            or normal.dtype.kind != "f"
            or not np.all(np.isfinite(normal))
        ):
            raise ValueError("texel arrays must be voxel indices (z, y, x), face ids 0..5 and finite normals")
        return cls(voxel, face, normal, bool(data["texel_centred"]) if "texel_centred" in data else False)
