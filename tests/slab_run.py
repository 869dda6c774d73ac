"""A small slab run directory for the evaluation tests (``make_run``)."""

import numpy as np

from inkopt.evaluation.baselines import extrusion_baseline, surface_baseline
from inkopt.io import save_npz
from inkopt.model import InkTable, Texels, Volume

V300 = 25.4 / 300
INKS3 = InkTable.from_names(["cyan", "magenta", "white"])
SHAPE = (6, 16, 24)


def make_run(d, table, kind="surface", shape=SHAPE):
    """A slab (default 24x16x6) with a 4-patch target on top; its mixture IS the surface (or extrusion) baseline."""
    tex = Texels.box_faces(shape, ["top"])
    quad = (tex.voxel[:, 1] >= shape[1] // 2) * 2 + (tex.voxel[:, 2] >= shape[2] // 2)
    colours = np.array([[0.05, 0.3, 0.6], [0.6, 0.1, 0.3], [0.8, 0.8, 0.8], [0.2, 0.5, 0.8]])
    target = colours[quad].astype(np.float32)
    ny, nx = shape[1:]
    pix = (np.arange(ny)[::-1, None] * nx + np.arange(nx)[None, :]).astype(np.int32)  # row 0 = largest y
    fixed = np.zeros(shape + (3,), np.float32)
    scene = {
        **tex.to_arrays(),
        "target_rgb": target,
        "kind": np.array("slab"),
        "fixed_share": fixed,
        "faces": np.array(["top"]),
        "pix_top": pix,
    }
    vol = Volume.from_mixture(voxel_mm=[V300] * 3, mixture=np.full(shape + (3,), 1 / 3, np.float32), inks=INKS3)
    fn = surface_baseline if kind == "surface" else extrusion_baseline
    vol = vol.with_mixture(fn(vol, tex, target, fixed, table))
    d.mkdir(parents=True, exist_ok=True)
    vol.save(d / "volume.npz")
    save_npz(d / "scene.npz", scene)
    return vol, scene
