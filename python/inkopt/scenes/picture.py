"""Input pictures: every image mode Pillow reads as sRGB colours with alpha, and resampling onto a face's texel
grid (what a slab's pictures, a mesh's texture and a slab's translucency mask share).

Colour spaces: an RGB picture with an embedded ICC profile other than sRGB (Adobe RGB, Display P3, ProPhoto, a
camera's or scanner's profile) is converted through its profile to sRGB by LittleCMS (Pillow's ImageCms), relative
colorimetric, so that its numbers are not read as sRGB numbers; colours outside sRGB's gamut are clipped to it
(8 bits a channel). A profile counts as sRGB when it maps every colour of a 17^3 grid to itself within one level,
so the many files that embed an sRGB profile are read exactly as before. CMYK with a profile and CIELAB take the same
path; RGB without a profile is sRGB. Greyscale profiles are not applied (grey is read as sRGB grey).
"""

from __future__ import annotations

import io
from functools import lru_cache

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
    elif rgb_profile(im, name) is not None:
        im = rgb_to_srgb(im, name)
    try:
        rgba = im.convert("RGBA")
    except (ValueError, OSError) as exc:
        raise ValueError(f"{name}: cannot convert image mode {mode} to RGB ({exc}); save it as RGB") from None
    return np.asarray(rgba, np.float32) / 255.0


def _to_srgb(im, icc: bytes | None, name: str):
    """``im`` through its ICC profile ``icc`` (None: CIELAB) to an sRGB PIL image (LittleCMS)."""
    from PIL import ImageCms

    try:
        src = ImageCms.createProfile("LAB") if icc is None else ImageCms.ImageCmsProfile(io.BytesIO(icc))
        return ImageCms.profileToProfile(im, src, ImageCms.createProfile("sRGB"), outputMode="RGB")
    except (ImageCms.PyCMSError, OSError, ValueError) as exc:
        raise ValueError(f"{name}: its {im.mode} colours cannot be converted to sRGB ({exc}); save it as RGB") from None


# Modes whose colours an RGB profile describes (a palette's entries are RGB).
_RGB_MODES = ("RGB", "RGBA", "RGBX", "RGBa", "P", "PA")


def rgb_profile(im, name: str = "picture") -> str | None:
    """The description of ``im``'s embedded RGB ICC profile when it is not sRGB (e.g. "Display P3"), else None
    (no profile, an sRGB one, or a mode other than RGB or palette). One-line ValueError naming ``name`` for a
    profile LittleCMS cannot read."""
    icc = im.info.get("icc_profile")
    if not icc or im.mode not in _RGB_MODES:
        return None
    try:
        described = _profile_description(bytes(icc))
    except ValueError as exc:
        raise ValueError(f"{name}: its embedded ICC profile cannot be read ({exc}); save it as sRGB") from None
    return described


@lru_cache(maxsize=16)
def _profile_description(icc: bytes) -> str | None:
    """None for an sRGB profile (every colour of a 17^3 grid maps to itself within one level), else the profile's
    description; ValueError for a profile that is not an RGB profile LittleCMS reads."""
    from PIL import Image, ImageCms

    try:
        profile = ImageCms.ImageCmsProfile(io.BytesIO(icc))
        space = profile.profile.xcolor_space.strip()
        if space != "RGB":
            raise ValueError(f"a {space} profile on RGB pixels")
        levels = np.minimum(np.arange(17) * 16, 255).astype(np.uint8)
        grid = np.stack(np.meshgrid(levels, levels, levels, indexing="ij"), -1).reshape(17, 289, 3)
        out = ImageCms.profileToProfile(Image.fromarray(grid, "RGB"), profile, ImageCms.createProfile("sRGB"))
        description = ImageCms.getProfileDescription(profile).strip() or "an unnamed profile"
    except (ImageCms.PyCMSError, OSError, TypeError) as exc:
        raise ValueError(" ".join(str(exc).split()) or type(exc).__name__) from None
    deviation = np.abs(np.asarray(out, np.int16) - grid.astype(np.int16)).max()
    return None if deviation <= 1 else description


def rgb_to_srgb(im, name: str):
    """An RGB or palette image with an embedded profile -> a PIL image in sRGB (LittleCMS, relative colorimetric:
    colours outside sRGB are clipped to its gamut): RGBA with the alpha unchanged where some pixel is not opaque,
    else RGB. One-line ValueError naming ``name`` for a profile LittleCMS cannot apply."""
    from PIL import ImageCms

    rgba = im.convert("RGBA")
    try:
        src = ImageCms.ImageCmsProfile(io.BytesIO(bytes(im.info["icc_profile"])))
        out = ImageCms.profileToProfile(
            rgba.convert("RGB"),
            src,
            ImageCms.createProfile("sRGB"),
            renderingIntent=ImageCms.Intent.RELATIVE_COLORIMETRIC,
            outputMode="RGB",
        )
    except (ImageCms.PyCMSError, OSError, ValueError) as exc:
        raise ValueError(f"{name}: its RGB colours cannot be converted to sRGB ({exc}); save it as sRGB") from None
    alpha = rgba.getchannel("A")
    if alpha.getextrema() != (255, 255):
        out.putalpha(alpha)
    return out


def resample(picture: np.ndarray, ny: int, nx: int) -> np.ndarray:
    """(H, W, 3) float32 -> (ny, nx, 3) float32, bilinear with anti-aliasing (in whatever space it is given:
    linear light for colours)."""
    from skimage.transform import resize  # scikit-image is slow to import; only slabs need it

    return resize(picture, (ny, nx, 3), order=1, anti_aliasing=True, mode="edge").astype(np.float32)
