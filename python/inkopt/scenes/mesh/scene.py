"""``inkopt optimize MESH``: optimise the ink mixture of every voxel of a textured 3D object.

Pipeline: load the mesh (``mesh.load_mesh``: z up, standing on z = 0, scaled to ``height_mm`` or by ``scale``
mm per model unit) -> voxelize it on the optimisation grid (``mesh.voxelize``, 300 DPI by default) -> a mixture
``Volume`` with the object's ``inside`` mask and shading ``normals`` (box boundary) and the scene (one texel per
surface voxel, target = the texture colour of the closest surface point) -> ``optimize.Optimization`` with
checkpoints and exact resume -> outputs in the run directory (docs/run-dir.md).

Which voxels are variables: every inside voxel, or with ``shell_mm`` only those less than ``shell_mm`` below the
surface (signed distance >= -shell_mm; surface voxels always). All other grid voxels, the deep core and the
voxels outside the object, get a fixed share of 100 % white: the core is printed white, and outside voxels (which
the renderer ignores) are not variables, so the optimiser's memory scales with the free voxels.

Besides the documented files, ``scene.npz`` holds ``free_mask`` (z, y, x) bool (the voxels that were
variables); ``fixed_share`` (z, y, x, N) is stored only while it has fewer than ``FIXED_SHARE_MAX_ENTRIES``
entries, since it equals ``one_hot(white) * ~free_mask`` and is large for big objects. ``volume.npz`` carries
``origin_mm`` (x, y, z of voxel (0, 0, 0)'s low corner) as an extra array.
"""
from __future__ import annotations

import resource
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .materials import InkTable
from .mesh import TexturedMesh, VoxelizedObject, bake_vertex_colors, load_mesh, render_views, voxelize, write_glb
from .slab import write_loss_png, write_report
from .volume import Volume, save_npz

FIXED_SHARE_MAX_ENTRIES = 50_000_000  # store scene.npz's dense fixed_share only below this many entries
DPI = 300.0
VIEW_SIZE = 320  # pixels per view in views.png (tests lower it)


def peak_rss_gb() -> float:
    """Peak resident memory of this process so far, GiB (Linux reports ru_maxrss in KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20


def free_voxels(vox: VoxelizedObject, shell_mm: float | None = None) -> np.ndarray:
    """(z, y, x) bool: the voxels the optimiser may change. All inside voxels, or with ``shell_mm`` (mm, > 0)
    those with sdf >= -shell_mm, plus every texel voxel (so a shell thinner than half a voxel still frees the
    surface)."""
    if shell_mm is None:
        return vox.inside.copy()
    if not (np.isfinite(shell_mm) and shell_mm > 0):
        raise ValueError(f"--shell-mm must be a positive thickness in mm, got {shell_mm}")
    free = vox.inside & (vox.sdf >= -np.float32(shell_mm))
    free[tuple(vox.texels.voxel.T)] = True
    return free


def white_fixed_share(free: np.ndarray, inks: InkTable) -> np.ndarray:
    """(z, y, x, N) float32 fixed shares: 100 % white where ``free`` is False, nothing where it is True."""
    if "white" not in inks.names:
        raise ValueError(f"the mesh pipeline fixes the voxels outside the object (and the core below --shell-mm) "
                         f"to white ink, but the ink set {list(inks.names)} has no 'white'")
    fixed = np.zeros(free.shape + (len(inks),), np.float32)
    fixed[..., inks.index("white")] = ~free
    return fixed


def scene_fixed_share(scene, inks: InkTable) -> np.ndarray:
    """The (z, y, x, N) float32 fixed shares of a run from its scene.npz arrays (a mapping): stored densely for
    small objects, else rebuilt from ``free_mask`` (100 % white wherever the mask is False)."""
    if "fixed_share" in scene:
        return np.asarray(scene["fixed_share"], np.float32)
    return white_fixed_share(np.asarray(scene["free_mask"], bool), inks)


@dataclass
class MeshScene:
    """A voxelized object ready to optimise.

    mesh: the loaded mesh (mm, z up); vox: its voxelization (``sdf`` dropped); volume: mixture Volume giving the
    geometry (inside, normals, box boundary, extra origin_mm) whose mixture *is* ``fixed_share`` (the same array;
    the optimiser ignores the base mixture); free: (z, y, x) bool variables; fixed_share: (z, y, x, N) float32.
    """

    mesh: TexturedMesh
    vox: VoxelizedObject
    volume: Volume
    free: np.ndarray
    fixed_share: np.ndarray
    shell_mm: float | None
    voxelize_seconds: float

    @property
    def height_mm(self) -> float:
        return float(np.ptp(self.mesh.solid_vertices[:, 2]))

    def scene_arrays(self, mesh_path: Path, up: str) -> dict:
        out = {**self.vox.texels.to_arrays(), "target_rgb": self.vox.targets.astype(np.float32),
               "kind": np.array("mesh"), "mesh_path": np.array(str(Path(mesh_path).resolve())),
               "mesh_scale": np.float64(self.mesh.mm_per_unit), "height_mm": np.float64(self.height_mm),
               "up": np.array(up), "origin_mm": self.vox.origin_mm, "voxel_mm": self.vox.voxel_mm,
               "texel_closest_mm": self.vox.closest_mm, "free_mask": self.free,
               "shell_mm": np.float64(np.nan if self.shell_mm is None else self.shell_mm)}
        if self.fixed_share.size < FIXED_SHARE_MAX_ENTRIES:
            out["fixed_share"] = self.fixed_share
        else:
            out["fixed_share_ink"] = np.array("white")  # fixed_share = one_hot(white) * ~free_mask
        return out


def build_mesh_scene(mesh_path, inks: InkTable, height_mm: float | None = None, scale: float | None = None,
                     shell_mm: float | None = None, dpi: float = DPI, up: str = "y") -> MeshScene:
    """Load and voxelize ``mesh_path``; exactly one of ``height_mm`` and ``scale`` (mm per model unit)."""
    if (height_mm is None) == (scale is None):
        raise ValueError("give exactly one of --height-mm and --scale")
    if not (np.isfinite(dpi) and dpi > 0):
        raise ValueError(f"--dpi must be positive, got {dpi}")
    if "white" not in inks.names:
        white_fixed_share(np.ones((1, 1, 1), bool), inks)  # raises the one-line error before the slow part
    if shell_mm is not None and not (np.isfinite(shell_mm) and shell_mm > 0):
        raise ValueError(f"--shell-mm must be a positive thickness in mm, got {shell_mm}")
    t0 = time.perf_counter()
    mesh = load_mesh(mesh_path, height_mm=height_mm, scale=scale, up=up)
    voxel_mm = 25.4 / dpi
    # The SDF is exact only within ``band`` voxels of the surface; the shell's boundary must lie inside it.
    band = 3.0 if shell_mm is None else max(3.0, np.ceil(shell_mm / voxel_mm) + 2.0)
    vox = voxelize(mesh, voxel_mm=voxel_mm, band=band)
    seconds = time.perf_counter() - t0
    free = free_voxels(vox, shell_mm)
    fixed = white_fixed_share(free, inks)
    # The base volume's mixture is ignored by the optimiser (it only gives geometry and inks): share the
    # fixed-share array instead of allocating another (z, y, x, N) array.
    vol = Volume(voxel_mm=vox.voxel_mm, mixture=fixed, inks=inks, g=inks.g, inside=vox.inside,
                 normals=vox.normals, boundary="box", extra={"origin_mm": vox.origin_mm})
    vox.sdf = None  # 4 bytes per grid voxel no longer needed
    return MeshScene(mesh, vox, vol, free, fixed, shell_mm, seconds)


def write_mesh_views(out: Path, scene: MeshScene, pred_rgb: np.ndarray, views: int = 4,
                     size: int | None = None) -> list[Path]:
    """prediction.glb, target.glb (vertex colours baked from the texels: target and predicted linear RGB (I, 3))
    and views.png (target row over prediction row, ``views`` azimuths, ``size`` pixels each)."""
    tx, vox = scene.vox.texels, scene.vox
    target = bake_vertex_colors(scene.mesh, vox.closest_mm, vox.targets, texel_normal=tx.normal)
    pred = bake_vertex_colors(scene.mesh, vox.closest_mm, np.clip(pred_rgb, 0, 1), texel_normal=tx.normal)
    paths = [out / "prediction.glb", out / "target.glb", out / "views.png"]
    write_glb(pred, paths[0])
    write_glb(target, paths[1])
    render_views(scene.mesh, target, pred, paths[2], views=views, size=size or VIEW_SIZE)
    return paths


def run_mesh(mesh_path, out_dir, inks: InkTable, cfg, height_mm: float | None = None,
             scale: float | None = None, shell_mm: float | None = None, dpi: float = DPI, up: str = "y",
             resume: bool = False, eval_spp: int | None = None, threads: int | None = None,
             progress: bool = False, log=print) -> dict:
    """The whole ``inkopt optimize`` run (see module docstring); returns the report (report.json)."""
    from .loss import delta_e76
    from .optimize import Optimization, evaluate_prediction
    from .render import Renderer

    t_start = time.perf_counter()
    out = Path(out_dir)
    scene = build_mesh_scene(mesh_path, inks, height_mm, scale, shell_mm, dpi, up)
    vol, tx = scene.volume, scene.vox.texels
    nz, ny, nx = vol.shape
    n_inside, n_free = int(scene.vox.inside.sum()), int(scene.free.sum())
    log(f"mesh {scene.height_mm:.1f} mm high: grid {nx} x {ny} x {nz} voxels ({vol.voxel_mm[0] * 1000:.1f} µm), "
        f"{n_inside} inside, {n_free} free, {len(tx)} texels; voxelized in {scene.voxelize_seconds:.1f} s")
    run = Optimization(vol, tx, scene.vox.targets, cfg, fixed_share=scene.fixed_share, threads=threads)
    scene.fixed_share = run.param.fixed_share  # the same array (no copy), kept for scene.npz
    ckpt = run.start(out, resume, log)
    save_npz(out / "scene.npz", scene.scene_arrays(Path(mesh_path), up))
    run.run(ckpt, progress=progress)
    final = run.volume()
    final.save(out / "volume.npz")

    # Final figures at higher spp with seeds unused by the optimisation; the start is reconstructed from the
    # configuration (identical to the first iterate whether or not the run was resumed).
    eval_spp = eval_spp or max(256, 4 * cfg.spp)
    eval_seed = 2**62 + cfg.seed
    res = Renderer(final, threads).render(tx, eval_spp, eval_seed, cfg.include_specular, progress)
    report = evaluate_prediction(run.loss, res.rgb, res.var_mean)
    del final
    initial = run.initial_volume()
    res0 = Renderer(initial, threads).render(tx, eval_spp, eval_seed, cfg.include_specular, progress)
    del initial
    init = evaluate_prediction(run.loss, res0.rgb, res0.var_mean)
    de = delta_e76(run.loss(res.rgb).lab, run.loss.target_lab)
    write_mesh_views(out, scene, res.rgb)
    write_loss_png(out, run.history)
    h = run.history
    n = max(len(h.seconds), 1)
    report = {
        "initial_delta_e76_mean": init["delta_e76_mean"], "initial_ssim": init["ssim"], **report,
        "delta_e76_max": float(de.max()),
        "iterations": run.iteration, "spp": cfg.spp, "eval_spp": eval_spp,
        "seconds": time.perf_counter() - t_start,
        "seconds_per_iteration": float(np.sum(h.seconds) / n),
        "time_split": {k: float(np.sum(getattr(h, k)) / n) for k in ("render_s", "gradient_s", "loss_s", "step_s")},
        "voxels": int(nz * ny * nx), "grid_zyx": [nz, ny, nx], "inside_voxels": n_inside, "free_voxels": n_free,
        "texels": len(tx), "voxelize_seconds": scene.voxelize_seconds, "peak_rss_gb": peak_rss_gb(),
        "shell_mm": shell_mm, "height_mm": scene.height_mm, "mesh_scale": scene.mesh.mm_per_unit,
        "mesh_path": str(Path(mesh_path).resolve()), "voxel_mm": [float(v) for v in vol.voxel_mm],
        "inks": list(inks.names), "gamma": list(cfg.gamma), "lr": cfg.step_size, "optimizer": cfg.optimizer,
        "param": cfg.param, "init": cfg.init, "seed": cfg.seed, "gradient": cfg.grad_method,
        "threads": threads,
    }
    write_report(out, report)
    return report
