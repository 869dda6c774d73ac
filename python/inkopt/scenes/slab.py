"""2.5D slabs: a box of voxels with pictures on its top (+z) and optionally bottom (-z) faces.

Picture orientation: the top picture is the slab seen from above (row 0 = largest y, column 0 = smallest x).
The bottom picture is the slab seen from below after turning it over about the y axis, like the back of a page:
row 0 = largest y, column 0 = **largest** x. Pictures are sRGB; they are resampled in linear light to the face's
texel grid (one texel per voxel face, 300 DPI by default) with anti-aliasing.

Translucency (``translucency``: a mask of the top picture's size, ``scenes.translucency``): the voxels under the
masked texels, down to ``translucency_depth_mm``, hold the mask's share of transparent ink as a fixed share.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from ..color import srgb_to_linear
from ..errors import ParameterError
from ..images import open_image
from ..model import FixedShares, InkTable, Texels, Translucency, Volume, transparent_ink
from ..pictures import error_figure
from ..rundir import RunDir, SceneRecord
from ..units import OPT_DPI, voxel_mm
from .picture import picture_rgba, resample, rgb_profile
from .spec import SlabSpec, check_slab_size
from .translucency import check_depth, load_mask, slab_translucency, translucency_fields

ASPECT_TOLERANCE = 0.02  # relative mismatch of picture and face aspect ratios allowed (resampling rounding)


def describe_picture(path: str | Path, face: str = "top") -> str:
    """ "FACE picture NAME (W x H px, MODE)": the colour source of a slab face, for the log and report.json."""
    with open_image(path, f"picture {path}", decode=False) as im:
        profile = rgb_profile(im, f"picture {path}")
        mode = im.mode + (f", converted to sRGB from ICC profile {profile}" if profile else "")
        return f"{face} picture {Path(path).name} ({im.size[0]} x {im.size[1]} px, {mode})"


def load_picture(path: str | Path) -> np.ndarray:
    """An image file of any mode Pillow reads (``picture.picture_rgba``) -> (H, W, 3) float32 linear RGB. Alpha
    is composited over white. One-line ValueError (``images.ImageError``) for a missing, unreadable or too large
    file."""
    with open_image(path, f"picture {path}") as im:
        arr = picture_rgba(im, f"picture {path}")
    rgb, alpha = arr[..., :3], arr[..., 3:]
    return srgb_to_linear(rgb * alpha + (1.0 - alpha)).astype(np.float32)


@dataclass
class SlabScene:
    """A slab ready to optimise (the ``Scene`` protocol of ``inkopt.scenes``)."""

    volume: Volume  # mixture form, all white; gives geometry and inks
    texels: Texels
    target_rgb: np.ndarray  # (I, 3) float32 linear
    faces: list[str]  # textured faces, texel order: "bottom" (if any) then "top"
    pix: dict  # face -> (H, W) int32 texel index per picture pixel
    size_mm: tuple = ()  # (W, H, D)
    translucency: Translucency | None = None
    colour_source: str = ""  # where the target colours come from, e.g. "picture top.png (1200 x 800 px, RGB)"
    kind = "slab"

    @cached_property
    def fixed_share(self) -> FixedShares | None:
        """The translucency constraint's transparent shares, or None (built once)."""
        return self.record().fixed_share(self.volume.inks, self.volume.shape)

    @property
    def warnings(self) -> list[str]:
        return []

    def record(self) -> SceneRecord:
        return SceneRecord(
            "slab", self.texels, self.target_rgb, list(self.faces), dict(self.pix), translucency=self.translucency
        )

    def describe(self) -> str:
        nz, ny, nx = self.volume.shape
        return (
            f"slab {nx} x {ny} x {nz} voxels ({self.volume.voxel_mm[0] * 1000:.1f} µm), {len(self.texels)} "
            f"texels, target colour from {self.colour_source or 'arrays'}, inks {','.join(self.volume.inks.names)}"
        )

    def report_fields(self) -> dict:
        return {
            "voxels": int(np.prod(self.volume.shape)),
            "texels": len(self.texels),
            "size_mm": [float(v) for v in self.size_mm],
            "colour_source": self.colour_source or "arrays",
            **translucency_fields(self.translucency),
        }

    def write_pictures(self, out: RunDir, pred_rgb: np.ndarray, delta_e: np.ndarray) -> list[Path]:
        """DIR/face_F.png: target | prediction | ΔE76 heat map, per textured face."""
        return [
            error_figure(out.face_picture_path(f), f, self.target_rgb, pred_rgb, delta_e, self.pix[f])
            for f in self.faces
        ]


def build_slab(
    top: np.ndarray,
    bottom: np.ndarray | None,
    size_mm,
    inks: InkTable,
    dpi: float = OPT_DPI,
    translucency: np.ndarray | None = None,
    translucency_depth_mm: float | None = None,
    translucency_source: str = "",
) -> SlabScene:
    """top, bottom: (H, W, 3) linear pictures; size_mm (W, H, D); translucency: (H, W) mask of transparent-ink
    shares in the top picture's pixels (``scenes.translucency``), down to ``translucency_depth_mm`` (None: the
    whole slab)."""
    check_slab_size(size_mm, dpi)
    w_mm, h_mm, d_mm = size_mm
    vox = voxel_mm(dpi)
    nx, ny, nz = (max(1, int(round(v / vox))) for v in (w_mm, h_mm, d_mm))
    for name, pic in (("top", top), ("bottom", bottom)):
        if pic is None:
            continue
        aspect = pic.shape[1] / pic.shape[0]
        if abs(aspect / (w_mm / h_mm) - 1.0) > ASPECT_TOLERANCE:
            raise ParameterError(
                f"the {name} picture is {pic.shape[1]}x{pic.shape[0]} px (aspect {aspect:.3f}) but "
                f"`size_mm` gives {w_mm:g}x{h_mm:g} mm (aspect {w_mm / h_mm:.3f}); "
                f"use `size_mm` {w_mm:g}x{w_mm / aspect:.4g}x{d_mm:g}"
            )
    faces = ["bottom", "top"] if bottom is not None else ["top"]
    texels = Texels.box_faces((nz, ny, nx), faces)
    # Texel order: bottom face (if any) then top, each C order over (y, x).
    offset = {"bottom": 0, "top": ny * nx if bottom is not None else 0}
    yy, xx = np.meshgrid(np.arange(ny)[::-1], np.arange(nx), indexing="ij")  # row 0 = largest y
    pix = {"top": (offset["top"] + yy * nx + xx).astype(np.int32)}
    if bottom is not None:
        pix["bottom"] = (offset["bottom"] + yy * nx + (nx - 1 - xx)).astype(np.int32)
    target = np.zeros((len(texels), 3), np.float32)
    for f in faces:
        pic = resample(top if f == "top" else bottom, ny, nx)
        target[pix[f].reshape(-1)] = pic.reshape(-1, 3)
    mixture = np.zeros((nz, ny, nx, len(inks)), np.float32)
    mixture[..., inks.index("white") if "white" in inks.names else 0] = 1.0
    vol = Volume.from_mixture(voxel_mm=(vox, vox, vox), mixture=mixture, inks=inks)
    tr = None
    if translucency is not None:
        tr = slab_translucency(
            translucency, top.shape[:2], (nz, ny, nx), vox, inks, translucency_depth_mm, translucency_source
        )
    return SlabScene(vol, texels, np.clip(target, 0.0, 1.0), faces, pix, tuple(size_mm), tr)


def build_slab_scene(spec: SlabSpec, inks: InkTable) -> SlabScene:
    """The slab scene of ``spec`` (``scenes.spec.SlabSpec``: picture files, size, grid, translucency mask file)
    for ink set ``inks``."""
    mask = None
    if spec.translucency is not None:
        transparent_ink(inks)
        check_depth(spec.translucency_depth_mm)
        mask = load_mask(spec.translucency)
    top = load_picture(spec.top)
    bottom = load_picture(spec.bottom) if spec.bottom else None
    tr_source = spec.translucency or ""
    scene = build_slab(top, bottom, spec.size_mm, inks, spec.dpi, mask, spec.translucency_depth_mm, tr_source)
    named = [describe_picture(spec.top, "top")]
    if spec.bottom:
        named.append(describe_picture(spec.bottom, "bottom"))
    scene.colour_source = ", ".join(named)
    return scene
