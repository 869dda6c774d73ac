"""Export of quantized ink labels as printer input: one RGBA PNG per layer (Stratasys-style voxel printing).

Folder layout written by ``write_png_slices`` (atomically: built in a hidden temporary sibling folder, then
renamed into place):

- ``slice_00000.png`` ... one RGBA PNG per printed layer, slice 0 = bottom layer (z = 0), names zero-padded to
  at least 5 digits and numbered consecutively;
- image columns = x (left to right = increasing x), rows = y with **row 0 = largest y**, so each image is the
  layer seen from above with +y pointing up; pixel (row r, column c) of slice k is label[k, Y - 1 - r, c];
- every ink has one fixed opaque colour (``DEFAULT_PALETTE``, overridable per ink name); empty voxels
  (label 255) get the background colour (transparent black by default);
- the PNGs carry the printer DPI (x, y) in their pHYs chunk; printer voxels are not square (600 × 300 DPI), so the
  images look stretched 2:1 in x in an ordinary viewer;
- ``manifest.json``: format, ``format_version`` (``MANIFEST_FORMAT``; a manifest without it is version 0, read
  as version 1), DPI (x, y), layer thickness (µm), layer count, image size, voxel size, orientation,
  the colour -> ink table with per-ink voxel counts and the printer's material name (``material``, null where
  the profile names none), background, the material limit applied and the printer profile (``printer``), and
  the digests of the files the slices were made from (``volume_digest``, ``quantized_digest``) where given.

The printer's software maps colours to materials; a printer holds only a few model materials per job
(``profiles.PRINTER_PROFILES``), so a job using more distinct inks than the limit is refused by ``check_job``
before anything is written. ``gcvf.py`` packs the same slices as a GrabCAD Voxel Print package, ``threemf.py``
writes a 3MF with the Volumetric extension and ``package.py`` reads all three back.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..io import FORMAT_KEY, publish, upgrade_format
from ..model import EMPTY
from ..units import MM_PER_INCH
from .profiles import PrinterProfile, material_name, printer_profile, resolve_max_materials, too_many_inks

FORMAT = "inkopt-png-slices"
#: the format version of manifest.json (``format_version``)
MANIFEST_FORMAT = 1

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


def _rgba(colour, what: str) -> tuple[int, int, int, int]:
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
    bg = _rgba(background, "background")
    out: list = []
    for name in ink_names:
        key = str(name).lower()
        if key in palette:
            out.append(_rgba(palette[key], f"palette entry '{name}'"))
        else:
            out.append(_rgba(DEFAULT_PALETTE[key], name) if key in DEFAULT_PALETTE else None)
    taken = {c[:3] for c in out if c is not None} | ({bg[:3]} if bg[3] == 255 else set())
    spare = (_rgba(s, "spare") for s in SPARE_COLOURS if tuple(s) not in taken)
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


def _is_slice_folder(path: Path) -> bool:
    if not any(path.iterdir()):
        return True
    try:
        return json.loads((path / "manifest.json").read_text()).get("format") == FORMAT
    except (OSError, ValueError, AttributeError):
        return False


@dataclass
class Job:
    """A checked print job: labels, printer voxel size, ink names, per-label voxel counts (256 entries, 255 =
    empty), the indices of the inks used, the material limit, the printer profile (or None) and the user's
    material names per ink (lower-case ink name -> name; they take precedence over the profile's)."""

    labels: np.ndarray
    vp: np.ndarray
    names: list
    counts: np.ndarray
    used: list
    limit: int | None
    profile: PrinterProfile | None
    overrides: dict = field(default_factory=dict)

    @property
    def dpi(self) -> tuple[float, float]:
        return MM_PER_INCH / self.vp[0], MM_PER_INCH / self.vp[1]

    def material(self, i: int) -> str | None:
        """The printer's material name for ink ``i``: the user's, else the profile's, else None."""
        return self.overrides.get(self.names[i].lower()) or material_name(self.profile, self.names[i])


def check_job(labels, voxel_mm_printer, ink_names, max_materials=None, printer=None, materials=None) -> Job:
    """Check a job before anything is written (every problem is a one-line ValueError).

    ``printer`` is a ``profiles.PRINTER_PROFILES`` key (its limit and material names); ``max_materials`` an int or
    a profile key overriding the limit (a key given there alone also names the printer); ``materials`` {ink name:
    material name} overriding the profile's names. A job using more distinct inks than the limit is refused with
    a line naming the inks and the limit.
    """
    labels = np.asarray(labels)
    if labels.ndim != 3 or labels.dtype != np.uint8 or min(labels.shape) < 1:
        raise ValueError(f"labels must be a non-empty uint8 (Z, Y, X) array, got {labels.dtype} {labels.shape}")
    vp = np.asarray(voxel_mm_printer, np.float64).reshape(-1)
    if vp.shape != (3,) or not np.all(np.isfinite(vp)) or np.any(vp <= 0):
        raise ValueError(f"voxel_mm_printer must be 3 positive sizes (x, y, z) in mm, got {vp}")
    names = [str(n) for n in ink_names]
    if not names or len(set(names)) != len(names) or len(names) >= EMPTY:
        raise ValueError(f"ink_names must be 1..{EMPTY - 1} unique names, got {names}")
    if printer is None and isinstance(max_materials, str):
        printer = max_materials
    profile = printer_profile(printer) if printer is not None else None
    limit = (
        resolve_max_materials(max_materials)
        if max_materials is not None
        else (profile.max_materials if profile else None)
    )
    counts = np.zeros(256, np.int64)
    for k in range(labels.shape[0]):
        counts += np.bincount(labels[k].ravel(), minlength=256)
    bad = np.flatnonzero(counts[len(names) : EMPTY])
    if bad.size:
        raise ValueError(f"labels use ink {len(names) + int(bad[0])} but only {len(names)} ink names are given")
    used = [i for i in range(len(names)) if counts[i] > 0]
    refusal = too_many_inks([names[i] for i in used], limit, profile.name if profile else None)
    if refusal:
        raise ValueError(refusal)
    overrides = {str(k).strip().lower(): str(v).strip() for k, v in (materials or {}).items()}
    unknown = sorted(set(overrides) - {n.lower() for n in names})
    if unknown or not all(overrides.values()):
        what = f"unknown ink '{unknown[0]}'" if unknown else "an empty name"
        raise ValueError(f"material names: {what}; give INK=NAME for the inks {names}")
    return Job(labels, vp, names, counts, used, limit, profile, overrides)


def slice_lut(names, palette=None, background=(0, 0, 0, 0)):
    """(lut (256, 4) uint8 label -> RGBA, ink colours, background RGBA); validates the palette."""
    colours = ink_colours(names, palette, background)
    bg = _rgba(background, "background")
    lut = np.zeros((256, 4), np.uint8)
    lut[:] = bg
    lut[: len(names)] = colours
    return lut, colours, bg


def slice_image(lut, layer):
    """One layer (Y, X) of labels as an RGBA image, row 0 = largest y (the module's orientation)."""
    from PIL import Image

    return Image.fromarray(lut[layer[::-1, :]])


def write_png_slices(
    labels,
    voxel_mm_printer,
    ink_names,
    out_dir,
    palette=None,
    max_materials=None,
    background=(0, 0, 0, 0),
    printer=None,
    materials=None,
    sources: dict | None = None,
) -> dict:
    """Write one RGBA PNG per layer plus ``manifest.json`` into ``out_dir`` (layout: module docstring).

    labels            uint8 (Z, Y, X) ink index per printer voxel, 255 = empty
    voxel_mm_printer  (x, y, z) printer voxel size in mm (DPI = 25.4 / size; layer thickness = z)
    ink_names         N names, label i -> ink_names[i]
    palette           optional {ink name: (r, g, b) | "#rrggbb"} overriding ``DEFAULT_PALETTE``
    max_materials     int, printer profile name (``profiles.PRINTER_PROFILES``) or None: refuse (ValueError) if the
                      labels use more distinct inks
    background        RGBA of empty voxels
    printer           printer profile key: its material limit and material names (manifest ``material``)
    materials         optional {ink name: material name} overriding the profile's names
    sources           {key: digest} copied into the manifest: the files the labels were made from
                      (``volume_digest``, ``quantized_digest``; ``io.file_digest``)
    An existing ``out_dir`` is replaced only if it is empty or an earlier slice folder (has our manifest).
    Returns the manifest (dict).
    """
    job = check_job(labels, voxel_mm_printer, ink_names, max_materials, printer, materials)
    lut, colours, bg = slice_lut(job.names, palette, background)
    labels, vp, names, counts, used = job.labels, job.vp, job.names, job.counts, job.used
    Z, Y, X = labels.shape

    out = Path(out_dir)
    if out.exists() and not (out.is_dir() and _is_slice_folder(out)):
        raise ValueError(f"{out} exists and is not an inkopt slice folder; refusing to replace it")
    out.parent.mkdir(parents=True, exist_ok=True)

    dpi = job.dpi
    width = max(5, len(str(Z - 1)))
    fname = f"slice_{{:0{width}d}}.png"
    manifest = {
        "format": FORMAT,
        "version": 1,
        FORMAT_KEY: MANIFEST_FORMAT,
        "dpi": {"x": round(dpi[0], 6), "y": round(dpi[1], 6)},
        "layer_thickness_um": round(vp[2] * 1000.0, 6),
        "voxel_mm": [float(v) for v in vp],
        "layer_count": Z,
        "image_size": {"width": X, "height": Y},
        "size_mm": [X * vp[0], Y * vp[1], Z * vp[2]],
        "files": {"pattern": f"slice_{{index:0{width}d}}.png", "first": fname.format(0), "last": fname.format(Z - 1)},
        "orientation": {
            "slices": "slice 0 = bottom layer (z = 0), +z up",
            "columns": "column 0 = smallest x, x increases to the right",
            "rows": "row 0 = largest y (view from above, +y up)",
        },
        "background": list(bg),
        "materials": [
            {
                "index": i,
                "ink": names[i],
                "color": list(colours[i]),
                "hex": "#{:02X}{:02X}{:02X}".format(*colours[i][:3]),
                "voxel_count": int(counts[i]),
                "material": job.material(i),
            }
            for i in range(len(names))
        ],
        "materials_used": len(used),
        "max_materials": job.limit,
        "printer": None if job.profile is None else {"key": job.profile.key, "name": job.profile.name},
        "empty_voxel_count": int(counts[EMPTY]),
        **{k: v for k, v in (sources or {}).items() if v is not None},
    }

    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent))
    old = None
    try:
        tmp.chmod(0o755)

        def save(k: int) -> None:  # Pillow's PNG encoder releases the GIL: threads overlap the zlib work
            slice_image(lut, labels[k]).save(tmp / fname.format(k), format="PNG", dpi=dpi, compress_level=1)

        with ThreadPoolExecutor(max_workers=min(8, os.cpu_count() or 1)) as pool:
            futures = [pool.submit(save, k) for k in range(Z)]
            try:
                for fut in futures:
                    fut.result()
            except BaseException:
                for fut in futures:
                    fut.cancel()
                raise
        (tmp / "manifest.json").write_text(json.dumps(manifest, indent=1) + "\n")
        if out.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".old", dir=out.parent))
            os.replace(out, old / "d")
        publish(tmp, out, directory=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        if old is not None and (old / "d").exists() and not out.exists():
            os.replace(old / "d", out)
        raise
    finally:
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    return manifest


def _pack_rgba(c) -> np.ndarray:
    """RGBA (..., 4) integers -> uint32 keys."""
    c = np.asarray(c, np.uint32)
    return (c[..., 0] << 24) | (c[..., 1] << 16) | (c[..., 2] << 8) | c[..., 3]


def read_png_slices(folder):
    """Read a folder written by ``write_png_slices``; returns ``(labels uint8 (Z, Y, X), manifest dict)``.

    Every pixel must carry an ink colour of the manifest or the background (ValueError otherwise).
    """
    from PIL import Image

    folder = Path(folder)
    try:
        manifest = json.loads((folder / "manifest.json").read_text())
    except (OSError, ValueError) as exc:
        raise ValueError(f"{folder}: no readable manifest.json ({type(exc).__name__})") from None
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        raise ValueError(f"{folder}: manifest format is not '{FORMAT}'")
    manifest = upgrade_format(
        manifest, kind="slice manifest", where=folder / "manifest.json", current=MANIFEST_FORMAT, upgrades={0: dict}
    )
    Z, Y, X = manifest["layer_count"], manifest["image_size"]["height"], manifest["image_size"]["width"]
    pack = _pack_rgba
    keys = [pack(m["color"]) for m in manifest["materials"]] + [pack(manifest["background"])]
    vals = [m["index"] for m in manifest["materials"]] + [EMPTY]
    order = np.argsort(keys)
    keys, vals = np.asarray(keys, np.uint32)[order], np.asarray(vals, np.uint8)[order]
    width = len(manifest["files"]["first"]) - len("slice_.png")
    labels = np.empty((Z, Y, X), np.uint8)
    for k in range(Z):
        path = folder / f"slice_{k:0{width}d}.png"
        with Image.open(path) as im:
            rgba = np.asarray(im.convert("RGBA"))
        if rgba.shape[:2] != (Y, X):
            raise ValueError(f"{path.name}: image size {rgba.shape[1]}x{rgba.shape[0]} differs from {X}x{Y}")
        p = pack(rgba)
        pos = np.clip(np.searchsorted(keys, p), 0, len(keys) - 1)
        if np.any(keys[pos] != p):
            raise ValueError(f"{path.name}: pixels with colours outside the manifest's table")
        labels[k] = vals[pos][::-1]
    return labels, manifest
