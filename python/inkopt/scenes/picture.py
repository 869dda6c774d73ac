"""Input pictures: every image mode Pillow reads as sRGB colours with alpha, and resampling onto a face's texel
grid (what a slab's pictures, a mesh's texture and a slab's translucency mask share)."""

from __future__ import annotations

import numpy as np

# Integer modes of 16-bit greyscale (PNG, TIFF): full scale is 65535, not 255 as ``Image.convert`` assumes.
_GREY16 = ("I;16", "I;16B", "I;16L", "I;16N", "I")


def picture_rgba(im, name: str = "picture") -> np.ndarray:
    """A PIL image of any mode -> (H, W, 4) float32 in [0, 1]: sRGB-encoded colour and straight alpha.

    16-bit greyscale (``I;16*``, and ``I`` as Pillow reads 16-bit PNGs) is scaled by 1/65535; float greyscale
    (``F``) must already lie in [0, 1]; CMYK with an embedded ICC profile goes through the profile to sRGB (without
    one, Pillow's naive inversion), CIELAB through LittleCMS; palette, 1-bit, grey+alpha and the rest through
    ``Image.convert("RGBA")``.
    Raises ValueError (one line, naming ``name``) for values outside the mode's range or a mode Pillow cannot
    convert."""
    mode = im.mode
    if mode in _GREY16 or mode == "F":
        grey = np.asarray(im, np.float64)
        scale = 1.0 if mode == "F" else 65535.0
        if grey.size and (not np.all(np.isfinite(grey)) or grey.min() < 0 or grey.max() > scale):
            raise ValueError(
                f"{name}: {mode} pixel values span {grey.min():g}..{grey.max():g}, outside 0..{scale:g}; "
                f"save it as 8- or 16-bit greyscale or RGB"
            )
        g = (grey / scale).astype(np.float32)
        return np.stack([g, g, g, np.ones_like(g)], axis=-1)
    if mode == "CMYK" and im.info.get("icc_profile"):
        im = _to_srgb(im, im.info["icc_profile"], name)
    elif mode == "LAB":
        im = _to_srgb(im, None, name)
    try:
        rgba = im.convert("RGBA")
    except (ValueError, OSError) as exc:
        raise ValueError(f"{name}: cannot convert image mode {mode} to RGB ({exc}); save it as RGB") from None
    return np.asarray(rgba, np.float32) / 255.0


def _to_srgb(im, icc: bytes | None, name: str):
    """``im`` through its ICC profile ``icc`` (None: CIELAB) to an sRGB PIL image (LittleCMS)."""
    import io

    from PIL import ImageCms

    try:
        src = ImageCms.createProfile("LAB") if icc is None else ImageCms.ImageCmsProfile(io.BytesIO(icc))
        return ImageCms.profileToProfile(im, src, ImageCms.createProfile("sRGB"), outputMode="RGB")
    except (ImageCms.PyCMSError, OSError, ValueError) as exc:
        raise ValueError(f"{name}: its {im.mode} colours cannot be converted to sRGB ({exc}); save it as RGB") from None


def resample(picture: np.ndarray, ny: int, nx: int) -> np.ndarray:
    """(H, W, 3) float32 -> (ny, nx, 3) float32, bilinear with anti-aliasing (in whatever space it is given:
    linear light for colours)."""
    from skimage.transform import resize  # scikit-image is slow to import; only slabs need it

    return resize(picture, (ny, nx, 3), order=1, anti_aliasing=True, mode="edge").astype(np.float32)
