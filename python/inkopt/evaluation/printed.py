"""The printed results of an evaluation (``evaluate``): the printer-resolution texels of a label grid, their map onto
the scene texels, and one renderer that serves every label volume of that grid (the run's quantized volume and the
baselines quantized like it).

A printer texel is a textured face of a printer voxel (meshes: one per printer surface voxel). Each is assigned to
the scene texel of the same face whose face centre is nearest in mm (meshes: the nearest scene texel), i.e. the
scene texel whose footprint contains it; a scene texel's colour is the mean of its printer texels (one that gets
none takes its nearest printer texel). With a texel sample (``sample.TexelSample``), only the printer texels of the
sampled scene texels (and the stand-ins of those that get none) are rendered: the map is made on all printer
texels first, so a sampled scene texel's colour is exactly what the full render averages for it.
Conventions: docs/conventions.md.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..model import EMPTY, Texels, Volume
from ..model.labelfile import LabelLayers, LabelLayersWriter
from ..printing.quantize import MixtureLayers, quantize
from ..printing.texelmap import average_to_scene, map_texels, printer_texels
from ..render import Renderer

__all__ = [
    "PrintedRenderer",
    "average_to_scene",
    "map_texels",
    "printer_texels",
    "quantized_baselines",
    "restrict",
    "same_inside",
]


def restrict(ptex: Texels, to_scene, stand_in, subset):
    """The printer texels of the scene texels ``subset`` (sorted int64 (S,)): those that map to them and the
    stand-ins of those that get none; returns (printer texels, their row in ``subset`` (int64), the stand-in
    (a row of the returned texels) of each ``subset`` texel, -1 where it has printer texels)."""
    subset = np.asarray(subset, np.int64)
    row = np.full(len(stand_in), -1, np.int64)
    row[subset] = np.arange(len(subset))
    mapped = np.flatnonzero(row[to_scene] >= 0)
    standing = stand_in[subset]
    keep = np.union1d(mapped, standing[standing >= 0])
    new_index = np.full(len(to_scene), -1, np.int64)
    new_index[keep] = np.arange(len(keep))
    sub_to = row[to_scene[keep]]  # -1 for a stand-in that maps to an unsampled scene texel
    sub_stand = np.where(standing >= 0, new_index[np.maximum(standing, 0)], -1)
    return ptex.subset(keep), sub_to, sub_stand


def quantized_baselines(sources: dict, voxel_mm, shape_p: tuple, dpi: tuple, meta: dict):
    """Each baseline of ``sources`` (name -> ``baselines.BaselineLayers`` on the optimisation grid of ``voxel_mm``;
    emptied as they go) quantized as the run's labels were (method, seed, upsampling and inks' order of
    ``meta["quantization"]``, at ``dpi``), never share-compensated (our method's step), a layer at a time into a
    temporary layered label file of the printer grid ``shape_p`` (a few bytes per layer of the homogeneous core).
    Yields (name, its labels ``Volume`` read a layer at a time with ``meta``'s geometry, the ``perf_counter`` its
    quantization began at); each file is removed when the next baseline begins, all of them on any exit."""
    q = replace(meta["quantization"], dpi=dpi, compensate=False)  # as ours was (its inks' order included)
    with tempfile.TemporaryDirectory(prefix="inkopt-baselines-") as tmp:
        for name in list(sources):
            t0 = time.perf_counter()
            src, path = sources.pop(name), Path(tmp) / f"{name}.layers"
            w = LabelLayersWriter(path, shape_p)
            try:
                quantize(MixtureLayers(src, voxel_mm, src.inside, meta["inks"], meta["g"], meta["ior"]), q, out=w)
                w.commit()
            except BaseException:
                w.abort()
                raise
            del src
            yield name, Volume.from_labels(labels=LabelLayers(path, shape_p), **meta), t0
            path.unlink()


def same_inside(a: Volume, b: Volume) -> bool:
    """Whether two volumes of one grid have the same inside voxels (``Volume.inside_mask``), compared a layer at a
    time (no grid-sized temporary)."""
    if a.shape != b.shape:
        return False

    def layer(v: Volume, z: int) -> np.ndarray:
        if v.inside is not None:
            return v.inside[z]
        return v.labels[z] != EMPTY if v.form == "labels" else np.ones(v.shape[1:], bool)

    return all(np.array_equal(layer(a, z), layer(b, z)) for z in range(a.shape[0]))


class PrintedRenderer:
    """Printer texels of a labels grid set up once (texels, texel map) and rendered on any labels volume of that grid
    (same shape, voxel size and inside voxels: the run's quantized volume and the baselines quantized like it),
    averaged onto the scene texels; the adaptive evaluation renders each volume in several passes.

    One renderer serves them all: its geometry (inside mask, distance fields, shading normals) is built for the
    first labels volume and kept; a later one only replaces the medium (``Renderer.set_volume``), which renders
    bit-identically to a renderer built for it. ``paths`` and ``events`` count the current volume's walks."""

    def __init__(
        self, qvol: Volume, scene: Texels, voxel_mm_scene, kind: str, threads=None, lighting=None, groups=None, **kw
    ):
        """``groups``: texel groups to render, each sorted scene texel indices (int64 (S,)) (a texel sample's
        points and windows), else one group of every texel; a group's results have its texels' rows, in order.
        ``factory`` (keyword): what builds the renderer, ``factory(volume, threads, lighting)`` (default
        ``Renderer``; a spectral run's band renders, whose results hold B band values per texel)."""
        self.factory = kw.pop("factory", None) or Renderer
        if kw:
            raise TypeError(f"unexpected arguments {sorted(kw)}")
        ptex = printer_texels(qvol, scene, kind)
        to_scene, stand_in = map_texels(ptex, qvol.voxel_mm, scene, voxel_mm_scene, per_face=kind != "mesh")
        self.all_printer_texels = len(ptex)
        if groups is None:
            self.maps = [(ptex, to_scene, stand_in, len(scene))]
        else:
            self.maps = [(*restrict(ptex, to_scene, stand_in, g), len(g)) for g in groups]
        self.shape, self.threads, self.lighting = qvol.shape, threads, lighting
        self.renderer, self.built_for, self.builds, self.paths, self.events = None, None, 0, 0, 0

    def use(self, labels_vol: Volume | None) -> None:
        """Render ``labels_vol`` from now on (its labels replace the previous volume's in the kept renderer), or
        free the renderer (None). ``labels_vol`` must have the printer texels' grid and inside voxels."""
        self.paths = self.events = 0
        if labels_vol is None:
            self.renderer = None
            return
        if labels_vol.shape != self.shape:
            raise ValueError(f"labels grid {labels_vol.shape} differs from the printer texels' {self.shape}")
        if self.renderer is None:
            self.renderer = self.factory(labels_vol, self.threads, self.lighting)
            self.built_for, self.builds = labels_vol, self.builds + 1
            return
        if not same_inside(labels_vol, self.built_for):
            raise ValueError("a printed result's inside voxels differ from those of the printer renderer's volume")
        self.renderer.set_volume(labels_vol)
        # the core keeps its own copy of the labels: the renderer's volume goes back to the one its geometry was
        # built for, so the caller's label grid is freed as soon as the caller drops it
        self.renderer.volume = self.built_for

    @property
    def printer_texels_rendered(self) -> int:
        """Printer texels of all groups (a printer texel in two groups counts twice)."""
        return sum(len(m[0]) for m in self.maps)

    def __call__(self, spp: int, seed: int, progress: bool = False, group: int = 0):
        """(rgb (I, C), var_mean (I, C)) (C = 3, or the bands of a spectral factory) on the scene texels of
        ``group`` from ``spp`` samples per scene texel, shared by its printer texels, and the printer spp used."""
        ptex, to_scene, stand_in, n_scene = self.maps[group]
        spp_p = max(1, int(np.ceil(spp * n_scene / len(ptex))))
        res = self.renderer.render(ptex, spp_p, seed, progress=progress)
        self.paths, self.events = self.paths + res.paths, self.events + res.events
        rgb, var = average_to_scene(
            res.rgb.astype(np.float64), res.var_mean.astype(np.float64), to_scene, stand_in, n_scene
        )
        return rgb, var, spp_p
