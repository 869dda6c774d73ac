"""What the slice formats (PNG slices, GCVF) share: one fixed opaque colour per ink, the label -> RGBA table, one
layer as an image and the one-line summary of a written job. ``ink_colours`` also gives a 3MF's display colours."""

from __future__ import annotations

import numpy as np

# Default opaque colour (R, G, B) of each ink name; used unless a palette entry overrides it.
DEFAULT_PALETTE: dict[str, tuple[int, int, int]] = {
    "cyan": (0, 255, 255),
    "magenta": (255, 0, 255),
    "yellow": (255, 255, 0),
    "black": (0, 0, 0),
    "white": (255, 255, 255),
    "transparent": (128, 128, 128),
    "clear": (128, 128, 128),
    "orange": (255, 128, 0),
    "cyan2": (0, 128, 255),
    "magenta2": (255, 0, 128),
    "yellow2": (192, 192, 0),
}
# Fallback colours for ink names missing from the palette, taken in order (skipping colours already in use).
SPARE_COLOURS = [
    (255, 0, 0),
    (0, 255, 0),
    (0, 0, 255),
    (128, 0, 0),
    (0, 128, 0),
    (0, 0, 128),
    (128, 128, 0),
    (128, 0, 128),
    (0, 128, 128),
    (64, 64, 64),
    (192, 192, 192),
]


def rgba(colour, what: str) -> tuple[int, int, int, int]:
    """``colour`` ("#RRGGBB", "#RRGGBBAA" or 3-4 integers in 0..255) as RGBA; ``what`` names it in errors."""
    if isinstance(colour, str):
        h = colour.lstrip("#")
        if len(h) not in (6, 8) or any(ch not in "0123456789abcdefABCDEF" for ch in h):
            raise ValueError(f"{what}: colour '{colour}' is not #RRGGBB or #RRGGBBAA")
        colour = [int(h[i : i + 2], 16) for i in range(0, len(h), 2)]
    c = [int(v) for v in colour]
    if len(c) == 3:
        c.append(255)
    if len(c) != 4 or any(not 0 <= v <= 255 for v in c):
        raise ValueError(f"{what}: colour {colour} must be 3 or 4 integers in 0..255")
    return tuple(c)


def ink_colours(ink_names, palette=None, background=(0, 0, 0, 0)) -> list[tuple[int, int, int, int]]:
    """Opaque RGBA colour of each ink (palette entry, else ``DEFAULT_PALETTE``, else the next spare colour).

    Colours must be distinct from each other and from ``background`` (otherwise a ValueError).
    """
    palette = {str(k).lower(): v for k, v in (palette or {}).items()}
    bg = rgba(background, "background")
    out: list = []
    for name in ink_names:
        key = str(name).lower()
        if key in palette:
            out.append(rgba(palette[key], f"palette entry '{name}'"))
        else:
            out.append(rgba(DEFAULT_PALETTE[key], name) if key in DEFAULT_PALETTE else None)
    taken = {c[:3] for c in out if c is not None} | ({bg[:3]} if bg[3] == 255 else set())
    spare = (rgba(s, "spare") for s in SPARE_COLOURS if tuple(s) not in taken)
    for i, name in enumerate(ink_names):
        if out[i] is None:
            out[i] = next(spare, None)
            if out[i] is None:
                raise ValueError(f"ink '{name}' has no palette colour and the spare colours are used up")
        if out[i][3] != 255:
            raise ValueError(f"ink '{name}': colour {out[i]} must be opaque (alpha 255)")
        if out[i] == bg or out[i][:3] in {c[:3] for c in out[:i]}:
            raise ValueError(f"ink '{name}': colour {out[i]} is already used by another ink or the background")
    return out


def pack_rgba(c) -> np.ndarray:
    """RGBA (..., 4) integers -> uint32 keys."""
    c = np.asarray(c, np.uint32)
    return (c[..., 0] << 24) | (c[..., 1] << 16) | (c[..., 2] << 8) | c[..., 3]


def slice_lut(names, palette=None, background=(0, 0, 0, 0)):
    """(lut (256, 4) uint8 label -> RGBA, ink colours, background RGBA); validates the palette."""
    colours = ink_colours(names, palette, background)
    bg = rgba(background, "background")
    lut = np.zeros((256, 4), np.uint8)
    lut[:] = bg
    lut[: len(names)] = colours
    return lut, colours, bg


def slice_image(lut, layer):
    """One layer (Y, X) of labels as an RGBA image, row 0 = largest y (the slice formats' orientation)."""
    from PIL import Image

    return Image.fromarray(lut[layer[::-1, :]])


def slices_line(summary: dict, layer_um: float) -> str:
    """One line on a written slice job: its ``layer_count``, ``image_size``, ``dpi`` and the used ``materials``
    (colour, and the printer's material name where known); ``layer_um`` its layer thickness in µm."""
    mats = [m for m in summary["materials"] if m["voxel_count"] > 0]
    used = ", ".join(
        f"{m['ink']} {'#{:02X}{:02X}{:02X}'.format(*m['color'][:3])}" + (f" = {m['material']}" if m["material"] else "")
        for m in mats
    )
    size, dpi = summary["image_size"], summary["dpi"]
    return (
        f"{summary['layer_count']} slices of {size['width']} x {size['height']} px "
        f"({dpi['x']:.0f} x {dpi['y']:.0f} DPI, {layer_um:.1f} um layers), {len(mats)} materials: {used}"
    )
