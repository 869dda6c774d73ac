"""The typed contents of a run's scene.npz (``SceneRecord``) and predictions.npz (``Predictions``), with their
format versions; ``rundir.RunDir`` reads and writes them."""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

from ..errors import ParameterError
from ..io import FORMAT_KEY, FormatError, upgrade_format
from ..model import FixedShares, InkTable, MeshInfo, Texels, Translucency, scene_fixed_shares
from ..model.volume import naming_file

#: scene.npz stores the dense (z, y, x, N) fixed_share only below this many entries (else: free_mask only)
FIXED_SHARE_MAX_ENTRIES = 50_000_000
#: the format version scene.npz is written in (``format_version``)
SCENE_FORMAT = 1
#: the format version predictions.npz is read up to (``format_version``): 2 adds a spectral run's band values; a file
#: without them is written as version 1, as before
PREDICTIONS_FORMAT = 2


@dataclass
class BandValues:
    """A spectral run's predictions as band reflectances, so that they can be shown under any light later.

    values: result name -> (I, B) float32 band values per scene texel (the rows of ``Predictions.rgb``);
    wavelengths_nm: (B,) float64 band centres; lights: light name -> (3, B) float64, the band matrix of its colour
    map (``spectral.lights.band_matrix``: band values -> CIE XYZ, Y of a white reflector 1), for the lights the
    run or its evaluation asked (a light file's spectrum may no longer be at hand).
    """

    values: dict[str, np.ndarray]
    wavelengths_nm: np.ndarray
    lights: dict[str, np.ndarray]

    def arrays(self) -> dict:
        out = {
            "band_names": np.array(list(self.values)),
            "wavelengths_nm": np.asarray(self.wavelengths_nm, np.float64),
            "light_names": np.array(list(self.lights)),
            "light_matrices": np.stack([np.asarray(m, np.float64) for m in self.lights.values()]),
        }
        out.update({f"bands_{n}": np.asarray(v, np.float32) for n, v in self.values.items()})
        return out

    @classmethod
    def from_arrays(cls, d, where: str) -> BandValues | None:
        """The band values of predictions.npz's arrays ``d`` (None: an RGB run's file)."""
        if "band_names" not in d:
            return None
        names = [str(n) for n in np.asarray(d["band_names"]).reshape(-1)]
        missing = [k for k in ("wavelengths_nm", "light_names", "light_matrices", *(f"bands_{n}" for n in names))]
        missing = [k for k in missing if k not in d]
        if missing:
            raise ValueError(f"{where} lacks {', '.join(missing)}; run 'inkopt evaluate' again")
        lights = [str(n) for n in np.asarray(d["light_names"]).reshape(-1)]
        nm = np.asarray(d["wavelengths_nm"], np.float64).reshape(-1)
        mats = np.asarray(d["light_matrices"], np.float64)
        if mats.shape != (len(lights), 3, len(nm)) or not lights:
            raise ValueError(f"{where}: light_matrices has shape {mats.shape}, expected ({len(lights)}, 3, {len(nm)})")
        values = {n: np.asarray(d[f"bands_{n}"], np.float32) for n in names}
        if any(v.ndim != 2 or v.shape[1] != len(nm) for v in values.values()):
            raise ValueError(f"{where}: band values do not have {len(nm)} bands")
        return cls(values, nm, dict(zip(lights, mats)))


@dataclass
class Predictions:
    """The contents of predictions.npz: predicted colours per scene texel.

    rgb: result name ("continuous", "quantized", "surface", "extrusion") -> (I, 3) float32 linear RGB on the
    scene's texels (the printed results rendered at printer resolution and averaged onto them, as ``inkopt
    evaluate`` does); source: "optimisation" or "evaluation"; spp: samples per scene texel of each result;
    volume_digest: ``io.file_digest`` of the volume.npz they were rendered from; lighting: the display lighting
    (``Lighting.describe()``, stored as JSON); bands: a spectral run's band values (``BandValues``; ``rgb`` then
    holds them as sRGB under the first light), else None (then the file is format version 1); texels: None (the rows
    are every scene texel), or (K,) int64 sorted scene texel indices of the rows (a texel sample's predictions,
    predictions_sample.npz; stored as ``texels``).
    """

    rgb: dict[str, np.ndarray]
    source: str
    spp: dict[str, int]
    volume_digest: str
    lighting: dict
    bands: BandValues | None = None
    texels: np.ndarray | None = None

    def arrays(self) -> dict:
        names = list(self.rgb)
        out = {
            FORMAT_KEY: np.int64(1 if self.bands is None else PREDICTIONS_FORMAT),
            "names": np.array(names),
            "source": np.array(self.source),
            "volume_digest": np.array(self.volume_digest),
            "lighting": np.array(json.dumps(self.lighting)),
            "spp": np.array([int(self.spp.get(n, 0)) for n in names], np.int64),
        }
        out.update({f"rgb_{n}": np.asarray(self.rgb[n], np.float32) for n in names})
        if self.bands is not None:
            out.update(self.bands.arrays())
        if self.texels is not None:
            out["texels"] = np.asarray(self.texels, np.int64)
        return out

    @classmethod
    def from_arrays(cls, d, where: str = "predictions.npz") -> Predictions:
        upgrades = {1: lambda a: a}  # version 2 only adds the optional band values
        d = upgrade_format(d, kind="predictions file", where=where, current=PREDICTIONS_FORMAT, upgrades=upgrades)
        names = [str(n) for n in np.asarray(d.get("names", [])).reshape(-1)]
        missing = [
            k for k in ("source", "volume_digest", "lighting", "spp", *(f"rgb_{n}" for n in names)) if k not in d
        ]
        if missing or not names:
            raise ValueError(f"{where} lacks {', '.join(missing) or 'names'}; run 'inkopt evaluate' again")
        spp = np.asarray(d["spp"]).reshape(-1)
        return cls(
            {n: np.asarray(d[f"rgb_{n}"], np.float32) for n in names},
            str(d["source"]),
            {n: int(v) for n, v in zip(names, spp)},
            str(d["volume_digest"]),
            json.loads(str(d["lighting"])),
            BandValues.from_arrays(d, where),
            None if "texels" not in d else np.asarray(d["texels"], np.int64).reshape(-1),
        )


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
        if np.asarray(self.target_rgb).dtype.kind not in "fiu":
            raise ValueError(f"scene target_rgb is {np.asarray(self.target_rgb).dtype}, not numbers")
        self.target_rgb = np.asarray(self.target_rgb, np.float32)
        if self.target_rgb.shape != (len(self.texels), 3) or len(self.texels) == 0:
            raise ValueError(
                f"scene target_rgb has shape {self.target_rgb.shape}, expected ({len(self.texels)}, 3) with texels"
            )
        if not np.all(np.isfinite(self.target_rgb)):
            raise ValueError("scene target_rgb holds non-finite colours")
        if self.free_mask is not None and np.ndim(self.free_mask) != 3:
            raise ValueError(f"scene free_mask has shape {np.shape(self.free_mask)}, expected (z, y, x)")

    def fixed_share(self, inks: InkTable, shape=None) -> FixedShares | None:
        """The (z, y, x, N) fixed ink shares: as stored, or rebuilt from ``free_mask`` (100 % white wherever the
        mask is False) and the translucency constraint (``model.scene_fixed_shares``), or None if the scene has
        no constraints. ``shape`` (z, y, x) checks it."""
        fixed = self.fixed
        if fixed is None:
            free = None if self.free_mask is None else np.asarray(self.free_mask, bool)
            core = None if self.mesh is None else self.mesh.core_share
            fixed = scene_fixed_shares(inks, free, self.translucency, core)
        if fixed is not None and (
            fixed.shape[-1] != len(inks) or (shape is not None and fixed.shape[:3] != tuple(shape))
        ):
            raise ValueError(
                f"scene fixed_share has shape {fixed.shape}, expected {tuple(shape or ())} x {len(inks)} inks"
            )
        return fixed

    def arrays(self) -> dict:
        """The arrays of scene.npz (the dense fixed shares only below ``FIXED_SHARE_MAX_ENTRIES`` entries)."""
        out = {
            FORMAT_KEY: np.int64(SCENE_FORMAT),
            **self.texels.to_arrays(),
            "target_rgb": self.target_rgb,
            "kind": np.array(self.kind),
        }
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
        """The record of scene.npz's arrays ``d`` (any format version this inkopt reads; ``where`` names the file
        in errors: arrays that make no record are one line naming it)."""
        try:
            return cls._from_arrays(d, where)
        except (TypeError, ValueError, KeyError, IndexError, OverflowError) as exc:
            raise naming_file(exc, where, ParameterError) from None

    @classmethod
    def _from_arrays(cls, d, where: str) -> SceneRecord:
        d = upgrade_format(
            d, kind="scene file", where=where, current=SCENE_FORMAT, upgrades={0: lambda a: _scene_from_0(a, where)}
        )
        for k in ("texel_voxel", "texel_face", "texel_normal", "target_rgb", "kind"):
            if k not in d:
                raise ValueError(f"{where} lacks array '{k}'")
        faces = [str(f) for f in np.asarray(d["faces"]).reshape(-1)] if "faces" in d else []
        kind = str(d["kind"])
        return cls(
            kind,
            Texels.from_arrays(d),
            d["target_rgb"],
            faces,
            {f: np.asarray(d[f"pix_{f}"]) for f in faces if f"pix_{f}" in d},
            np.asarray(d["free_mask"], bool) if "free_mask" in d else None,
            FixedShares.from_dense(d["fixed_share"]) if "fixed_share" in d else None,
            MeshInfo.from_arrays(d) if kind == "mesh" and "mesh_path" in d else None,
            Translucency.from_arrays(d),
        )


def _scene_from_0(d: dict, where) -> dict:
    """scene.npz version 0 -> 1: the same arrays; the pre-release layouts (no ``kind``; a mesh record without
    ``height_mm``, ``up`` or ``shell_mm``) are refused in one line."""
    missing = [k for k in ("kind",) if k not in d]
    if str(d.get("kind")) == "mesh" and "mesh_path" in d:
        missing += [k for k in ("height_mm", "up", "shell_mm") if k not in d]
    if missing:
        raise FormatError(
            f"{where} lacks {', '.join(missing)}: a pre-release layout; rerun the optimisation with this inkopt"
        )
    return d
