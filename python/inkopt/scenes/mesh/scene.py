"""The scene of a textured 3D object (``inkopt optimize MESH``).

Load the mesh (``load.load_mesh``: z up, standing on z = 0, scaled to ``height_mm`` or by ``scale`` mm per model unit)
-> voxelize it on the optimisation grid (``voxelize.voxelize``, 300 DPI by default) -> a label ``Volume`` (white inside)
with the object's ``inside`` mask, shading ``normals`` and ``origin_mm`` (box boundary), one texel per surface voxel
whose target is the texture colour of the closest surface point.

Which voxels are variables: every inside voxel, or with ``shell_mm`` only those less than ``shell_mm`` below the
surface (signed distance >= -shell_mm; surface voxels always). All other grid voxels, the deep core and the
voxels outside the object, hold the fixed mixture ``core`` (``model.fixed.core_shares``: 100 % white by default,
the optimiser's white start, or given ink shares): the core is printed as that mixture, and outside voxels (which
the renderer ignores) are not variables, so the optimiser's memory scales with the free voxels.

``scene.npz`` (``rundir.SceneRecord``) holds ``free_mask`` (z, y, x) bool (the voxels that were variables);
the dense fixed shares only for small objects, since they equal ``core * ~free_mask`` (the core's shares are
``MeshInfo.core_share``) plus the translucency constraint, which it stores sparsely.

Translucency (``translucency``: "alpha" for the texture's alpha channel, or a mask in texture space;
``scenes.translucency``): inside voxels within ``translucency_depth_mm`` of the surface (None: all) hold their
nearest texel's share of transparent ink as a fixed share; a white core voxel that a region reaches becomes that
share of transparent and the rest white.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...errors import ParameterError
from ...model import (
    Band,
    FixedShares,
    InkTable,
    MeshInfo,
    Translucency,
    Volume,
    transparent_ink,
)
from ...model.fixed import DEFAULT_CORE, core_shares
from ...model.media import InsideLabels
from ...model.volume import check_grid_budget
from ...rundir import RunDir, SceneRecord
from ...units import voxel_mm
from ..spec import MeshSpec
from ..translucency import ALPHA, check_depth, load_mask, translucency_fields
from .checks import check_mesh_inputs
from .load import TexturedMesh, load_mesh
from .source import describe_colour_source
from .translucency import mesh_texel_share, mesh_translucency
from .views import bake_vertex_colors, render_views, write_glb
from .voxelize import VoxelizedObject, voxelize

VIEW_SIZE = 320  # pixels per view in views.png (tests lower it)


def free_voxels(vox: VoxelizedObject, shell_mm: float | None = None) -> np.ndarray:
    """(z, y, x) bool: the voxels the optimiser may change. All inside voxels, or with ``shell_mm`` (mm, > 0, less
    than the voxelization's exact-distance band ``vox.depth.band_mm``) those at most ``shell_mm`` below the surface
    (``NearDepth.within``), plus every texel voxel (so a shell thinner than half a voxel still frees the surface)."""
    if shell_mm is None:
        return vox.inside.dense()
    if not (np.isfinite(shell_mm) and shell_mm > 0):
        raise ParameterError(f"`shell_mm` must be a positive thickness in mm, got {shell_mm}")
    free = np.zeros(vox.inside.shape, bool)
    free.reshape(-1)[vox.depth.within(shell_mm)] = True
    free[tuple(vox.texels.voxel.T)] = True
    return free


@dataclass
class MeshScene:
    """A voxelized object ready to optimise.

    mesh: the loaded mesh (mm, z up); vox: its voxelization (``depth`` dropped); volume: a label Volume giving the
    geometry (inside, normals, box boundary, origin_mm) and inks (white labels inside; the optimiser takes its
    fixed shares from ``fixed_share``); fixed_share: the (z, y, x, N) fixed ink shares
    (:class:`~inkopt.model.FixedShares`), whose free mask (a bit per voxel) says which voxels are variables
    (``free``).
    """

    mesh: TexturedMesh
    vox: VoxelizedObject
    volume: Volume
    fixed_share: FixedShares
    shell_mm: float | None
    voxelize_seconds: float

    mesh_path: str = ""
    up: str = "y"
    translucency: Translucency | None = None
    core: str = DEFAULT_CORE
    shell_chosen: str | None = None  # why the shell was chosen rather than given (``scenes.spec.MeshSpec``)
    kind = "mesh"

    @property
    def free(self) -> np.ndarray:
        """(z, y, x) bool: the voxels that are variables (unpacked from ``fixed_share``'s bits: a new array)."""
        return self.fixed_share.free

    @property
    def texels(self):
        return self.vox.texels

    @property
    def target_rgb(self) -> np.ndarray:
        return self.vox.targets

    @property
    def warnings(self) -> list:
        """One-line notes about the input for the log (the mesh's: ``TexturedMesh.warnings``)."""
        return list(self.mesh.warnings)

    @property
    def height_mm(self) -> float:
        return float(np.ptp(self.mesh.solid_vertices[:, 2]))

    def record(self) -> SceneRecord:
        vox = self.vox
        info = MeshInfo(
            self.mesh_path,
            float(self.mesh.mm_per_unit),
            self.height_mm,
            self.up,
            vox.origin_mm,
            vox.voxel_mm,
            vox.closest_mm,
            self.shell_mm,
            self.fixed_share.held,
        )
        return SceneRecord(
            "mesh",
            vox.texels,
            vox.targets,
            free_mask=self.free,
            fixed=self.fixed_share,
            mesh=info,
            translucency=self.translucency,
        )

    def describe(self) -> str:
        nz, ny, nx = self.volume.shape
        return (
            f"mesh {self.height_mm:.1f} mm high, target colour from {describe_colour_source(self.mesh)}: "
            f"grid {nx} x {ny} x {nz} voxels "
            f"({self.volume.voxel_mm[0] * 1000:.1f} µm), {self.vox.inside.count} inside, "
            f"{self.fixed_share.mask.count} free, {len(self.texels)} texels; voxelized in {self.voxelize_seconds:.1f} s"
        )

    def report_fields(self) -> dict:
        nz, ny, nx = self.volume.shape
        return {
            "voxels": int(nz * ny * nx),
            "grid_zyx": [nz, ny, nx],
            "inside_voxels": self.vox.inside.count,
            "free_voxels": self.fixed_share.mask.count,
            "texels": len(self.texels),
            "voxelize_seconds": self.voxelize_seconds,
            "shell_mm": self.shell_mm,
            "core": self.core,
            "core_shares": {n: float(v) for n, v in zip(self.volume.inks.names, self.fixed_share.held) if v > 0},
            "height_mm": self.height_mm,
            "mesh_scale": self.mesh.mm_per_unit,
            "mesh_path": self.mesh_path,
            "colour_source": describe_colour_source(self.mesh),
            "voxel_mm": [float(v) for v in self.volume.voxel_mm],
            **translucency_fields(self.translucency),
            **({} if self.shell_chosen is None else {"shell_chosen": self.shell_chosen}),
        }

    def write_pictures(
        self,
        out: RunDir,
        pred_rgb: np.ndarray,
        delta_e: np.ndarray | None = None,
        views: int = 4,
        size: int | None = None,
    ) -> list[Path]:
        """prediction.glb, target.glb (vertex colours baked from the texels: target and predicted linear RGB
        (I, 3)) and views.png (target row over prediction row, ``views`` azimuths, ``size`` pixels each)."""
        tx, vox = self.vox.texels, self.vox
        target = bake_vertex_colors(self.mesh, vox.closest_mm, vox.targets, texel_normal=tx.normal)
        pred = bake_vertex_colors(self.mesh, vox.closest_mm, np.clip(pred_rgb, 0, 1), texel_normal=tx.normal)
        paths = [out.prediction_glb_path, out.target_glb_path, out.views_picture_path]
        write_glb(pred, paths[0])
        write_glb(target, paths[1])
        render_views(self.mesh, target, pred, paths[2], views=views, size=size or VIEW_SIZE)
        return paths


#: a lower bound of the memory per grid voxel while a mesh is voxelized and rendered (bytes): the inside and free
#: masks (1 each) and the core's signed-distance byte
MIN_BYTES_PER_GRID_VOXEL = 3


def check_grid_size(mesh: TexturedMesh, dpi: float) -> None:
    """One-line error, before voxelizing, for a mesh whose grid at ``dpi`` does not fit
    (``model.volume.check_grid_budget`` at ``MIN_BYTES_PER_GRID_VOXEL``)."""
    size = np.ptp(mesh.solid_vertices, axis=0)  # (x, y, z) mm
    check_grid_budget(mesh.source, size, dpi, MIN_BYTES_PER_GRID_VOXEL, "height_mm")


def load_spec_mesh(spec: MeshSpec) -> TexturedMesh:
    """The placed, textured mesh of ``spec`` (``load.load_mesh``), not voxelized."""
    return load_mesh(
        spec.path,
        height_mm=spec.height_mm,
        scale=spec.scale,
        up=spec.up,
        texture=spec.texture,
        constant_color=spec.constant_color,
    )


def build_mesh_scene(spec: MeshSpec, inks: InkTable) -> MeshScene:
    """Load and voxelize the mesh of ``spec`` (``scenes.spec.MeshSpec``: file, placement, shell, grid,
    translucency: "alpha", the texture's alpha channel, or a mask file in texture space, down to its depth below
    the surface, the whole object without one) for ink set ``inks``."""
    check_mesh_inputs(spec.shell_mm, inks)
    mask, depth_mm = None, None
    if spec.translucency is not None:
        transparent_ink(inks)
        depth_mm = check_depth(spec.translucency_depth_mm)
        mask = None if spec.translucency == ALPHA else load_mask(spec.translucency)
    t0 = time.perf_counter()
    mesh = load_spec_mesh(spec)
    vmm = voxel_mm(spec.dpi)
    check_grid_size(mesh, spec.dpi)
    # Depths below the surface are exact and kept only within ``band`` voxels of it; the shell's and the translucent
    # regions' boundaries must lie inside it.
    band = 3.0
    for d in (spec.shell_mm, depth_mm):
        band = band if d is None else max(band, np.ceil(d / vmm) + 2.0)
    vox = voxelize(mesh, voxel_mm=vmm, band=band)
    seconds = time.perf_counter() - t0
    core = core_shares(spec.core, inks)
    fixed = FixedShares(free_voxels(vox, spec.shell_mm), core)  # the free mask kept as bits
    tr = None
    if spec.translucency is not None:  # before the depths are dropped
        tr = mesh_translucency(vox, mesh_texel_share(mesh, vox, mask), inks, depth_mm, spec.translucency)
        if tr is not None:
            fixed = tr.applied(fixed, inks)
    vox.depth = None  # the near voxels' depths are no longer needed (before the volume's arrays are made)
    # The base volume's medium is not the optimiser's (it takes geometry and inks from it, and the fixed shares
    # from ``fixed``): white labels inside, read from the inside mask (nothing per voxel of its own).
    vol = Volume(
        vox.voxel_mm,
        InsideLabels(vox.inside, inks.index("white"), inks),
        g=inks.g,
        inside=vox.inside,
        normals=vox.normals,
        boundary="box",
        origin_mm=vox.origin_mm,
        band=None if spec.shell_mm is None else Band.of_fixed(vox.inside, fixed),  # a core below the shell
    )
    path = str(Path(spec.path).resolve())
    return MeshScene(mesh, vox, vol, fixed, spec.shell_mm, seconds, path, spec.up, tr, spec.core, spec.shell_chosen)
