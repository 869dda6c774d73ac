"""PNG slice stack: one RGBA PNG per layer plus ``manifest.json`` (Stratasys-style voxel printing).

Folder layout written by ``write_png_slices`` (atomically: built in a hidden temporary sibling folder, then
renamed into place):

- ``slice_00000.png`` ... one RGBA PNG per printed layer, slice 0 = bottom layer (z = 0), names zero-padded to
  at least 5 digits and numbered consecutively;
- image columns = x (left to right = increasing x), rows = y with **row 0 = largest y**, so each image is the
  layer seen from above with +y pointing up; pixel (row r, column c) of slice k is label[k, Y - 1 - r, c];
- every ink has one fixed opaque colour (``slices.DEFAULT_PALETTE``, overridable per ink name); empty voxels
  (label 255) get the background colour (transparent black by default);
- the PNGs carry the printer DPI (x, y) in their pHYs chunk; printer voxels are not square (600 × 300 DPI), so the
  images look stretched 2:1 in x in an ordinary viewer;
- ``manifest.json``: format, ``format_version`` (``MANIFEST_FORMAT``; a manifest without it is version 0, read
  as version 1), DPI (x, y), layer thickness (µm), layer count, image size, voxel size, orientation,
  the colour -> ink table with per-ink voxel counts and the printer's material name (``material``, null where
  the profile names none), background, the material limit applied and the printer profile (``printer``), and
  the digests of the files the slices were made from (``volume_digest``, ``quantized_digest``) where given.

The printer's software maps colours to materials; a printer holds only a few model materials per job
(``profiles.PRINTER_PROFILES``), so a job using more distinct inks than the limit is refused (``job.tally``)
before anything is written. ``read_png_slices`` reads a folder back; ``PngSlices.check`` also checks that the
slices agree with the manifest (``inkopt inspect``).
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from ...io import FORMAT_KEY, check_output, publish, upgrade_format
from ...model import EMPTY
from ...rundir import QUANTIZED_DIGEST, VOLUME_DIGEST
from .inspection import PackageError, PackageReport, Scan, about, check_counts, decoder, layer_files
from .job import InkCounts, PrintJob, tally
from .members import decode_png
from .slices import rgba, slice_image, slice_lut, slices_line

if TYPE_CHECKING:
    from ...rundir import RunDir

MANIFEST_ID = "inkopt-png-slices"  # the manifest's "format"
#: the format version of manifest.json (``format_version``)
MANIFEST_FORMAT = 1
MANIFEST = "manifest.json"


def _is_slice_folder(path: Path) -> bool:
    if not any(path.iterdir()):
        return True
    try:
        return json.loads((path / MANIFEST).read_text()).get("format") == MANIFEST_ID
    except (OSError, ValueError, AttributeError):
        return False


def _manifest(job: PrintJob, tallied: InkCounts, colours, bg, width: int) -> dict:
    """manifest.json of ``job`` (module docstring) for slices named with ``width`` digits."""
    vp, names, counts = job.voxels.voxel_mm, job.inks, tallied.counts
    Z, Y, X = job.voxels.shape
    dpi = job.voxels.dpi
    fname = f"slice_{{:0{width}d}}.png"
    sources = {VOLUME_DIGEST: job.provenance.volume_digest, QUANTIZED_DIGEST: job.provenance.digest}
    return {
        "format": MANIFEST_ID,
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
                "material": job.material(names[i]),
            }
            for i in range(len(names))
        ],
        "materials_used": len(tallied.used),
        "max_materials": job.limit,
        "printer": None if job.printer is None else {"key": job.printer.key, "name": job.printer.name},
        "empty_voxel_count": int(counts[EMPTY]),
        **{k: v for k, v in sources.items() if v is not None},
    }


def _save_slices(folder: Path, labels, lut, dpi, fname: str) -> None:
    """Every layer of ``labels`` as ``folder/fname.format(k)``."""

    def save(k: int) -> None:  # Pillow's PNG encoder releases the GIL: threads overlap the zlib work
        slice_image(lut, labels[k]).save(folder / fname.format(k), format="PNG", dpi=dpi, compress_level=1)

    with ThreadPoolExecutor(max_workers=min(8, os.cpu_count() or 1)) as pool:
        futures = [pool.submit(save, k) for k in range(labels.shape[0])]
        try:
            for fut in futures:
                fut.result()
        except BaseException:
            for fut in futures:
                fut.cancel()
            raise


def _replace_folder(out: Path, fill) -> None:
    """Build a folder with ``fill(tmp)`` in a temporary sibling and put it in place of ``out``; on any error the
    old ``out`` stays as it was and nothing is left behind."""
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent))
    old = None
    try:
        tmp.chmod(0o755)
        fill(tmp)
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


def write_png_slices(job: PrintJob, out_dir, background=(0, 0, 0, 0)) -> dict:
    """Write one RGBA PNG per layer of ``job``'s labels plus ``manifest.json`` into ``out_dir`` (layout: module
    docstring); ``background``: the RGBA of empty voxels. An existing ``out_dir`` is replaced only if it is empty
    or an earlier slice folder (has our manifest). Returns the manifest (dict)."""
    tallied = tally(job)
    lut, colours, bg = slice_lut(job.inks, job.palette, background)
    out = Path(out_dir)
    check_output(out, _is_slice_folder, "an inkopt slice folder", folder=True)
    out.parent.mkdir(parents=True, exist_ok=True)
    width = max(5, len(str(job.voxels.shape[0] - 1)))
    manifest = _manifest(job, tallied, colours, bg, width)

    def fill(tmp: Path) -> None:
        _save_slices(tmp, job.voxels.labels, lut, job.voxels.dpi, f"slice_{{:0{width}d}}.png")
        (tmp / MANIFEST).write_text(json.dumps(manifest, indent=1) + "\n")

    _replace_folder(out, fill)
    return manifest


def _check_manifest(man) -> None:
    """A ValueError unless ``man`` holds every key a reader needs with a value of its kind: counts 1 .. 2^31 - 1,
    positive DPI and layer thickness, RGBA colours, 1 .. 254 materials with an ink name and a voxel count."""
    if not isinstance(man, dict) or man.get("format") != MANIFEST_ID:
        raise ValueError(f"format is not {MANIFEST_ID}")
    counts = [man["layer_count"], man["image_size"]["width"], man["image_size"]["height"]]
    if not all(isinstance(v, int) and not isinstance(v, bool) and 1 <= v < 2**31 for v in counts):
        raise ValueError(f"layer_count and image_size must be counts 1 .. 2^31 - 1, got {counts}")
    sizes = [man["dpi"]["x"], man["dpi"]["y"], man["layer_thickness_um"]]
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and 0 < v < float("inf") for v in sizes):
        raise ValueError(f"dpi and layer_thickness_um must be positive numbers, got {sizes}")
    rgba(man["background"], "background")
    mats = man["materials"]
    if not isinstance(mats, list) or not 1 <= len(mats) < EMPTY:
        raise ValueError(f"materials must be a list of 1 .. {EMPTY - 1} materials")
    for m in mats:
        rgba(m["color"], f"material {m['ink']!r}")
        if not isinstance(m["ink"], str) or not isinstance(m["voxel_count"], int) or m["voxel_count"] < 0:
            raise ValueError(f"material {m['ink']!r} needs an ink name and a voxel count")


def _load_manifest(folder: Path) -> dict:
    """manifest.json of a slice folder, brought to ``MANIFEST_FORMAT``, with every key a reader needs."""
    try:
        man = json.loads((folder / MANIFEST).read_text())
        _check_manifest(man)
    except (OSError, ValueError, KeyError, TypeError, RecursionError) as exc:
        text = " ".join(str(exc).split())
        raise PackageError(f"{folder}/{MANIFEST} is missing or malformed ({type(exc).__name__}: {text})") from None
    where = folder / MANIFEST
    return upgrade_format(man, kind="slice manifest", where=where, current=MANIFEST_FORMAT, upgrades={0: dict})


def _scan(folder: Path, keep_layers=(), labels: bool = False) -> tuple[dict, Scan]:
    """The manifest and every slice decoded through its colour table and counted against it."""
    man = _load_manifest(folder)
    N, W, H = man["layer_count"], man["image_size"]["width"], man["image_size"]["height"]
    mats = man["materials"]
    files = layer_files([p.name for p in folder.iterdir()], r"slice_(\d+)\.png", N, MANIFEST)
    decode = decoder([rgba(m["color"], m["ink"]) for m in mats], rgba(man["background"], "background"))
    scan = Scan(N, H, W, len(mats), keep_layers, labels)
    for k, name in enumerate(files):
        scan.add(k, decode(name, decode_png(folder / name, name, (W, H))))
    check_counts([m["ink"] for m in mats], [m["voxel_count"] for m in mats], scan.counts, MANIFEST)
    return man, scan


def read_png_slices(folder):
    """Read a folder written by ``write_png_slices``; returns ``(labels uint8 (Z, Y, X), manifest dict)``.

    Every pixel must carry an ink colour of the manifest or the background, and the slices must agree with the
    manifest (``PackageError`` otherwise; a manifest of a newer format version is a ``FormatError``)."""
    man, scan = _scan(Path(folder), labels=True)
    return scan.labels, man


def check_png_slices(path: Path, keep_layers=(), labels: bool = False) -> tuple[PackageReport, Scan]:
    """Read the slice folder ``path`` back and check it (``inspection``); its report and scan. Errors name
    ``path``."""
    with about(path):
        man, scan = _scan(path, keep_layers, labels)
        box = scan.box()
    materials = [
        {"name": m.get("material") or m["ink"], "ink": m["ink"], "color": m["color"], "voxel_count": int(v)}
        for m, v in zip(man["materials"], scan.counts, strict=True)
    ]
    # the manifest records the quantized file the slices were made from (``quantized_digest``)
    digest = man.get(QUANTIZED_DIGEST)
    source = {"source": "quantized.npz", "digest": digest} if digest else None
    dpi, layer_um = (man["dpi"]["x"], man["dpi"]["y"]), man["layer_thickness_um"]
    N, W, H = man["layer_count"], man["image_size"]["width"], man["image_size"]["height"]
    report = PackageReport(PngSlices.name, str(path), N, W, H, dpi, layer_um, materials, box, source)
    return report, scan


@dataclass(frozen=True)
class PngSlices:
    """The PNG slice stack as a ``formats.Format``: a folder; ``background`` the RGBA of empty voxels."""

    background: tuple = (0, 0, 0, 0)
    name = "png-slices"
    suffix = ""  # a folder
    default_printer = "generic"
    takes_mixture = False

    def write(self, job: PrintJob, path) -> dict:
        return write_png_slices(job, path, self.background)

    def recognises(self, path: Path) -> bool:
        return path.is_dir()

    def check(self, path: Path, keep_layers=(), labels: bool = False) -> tuple[PackageReport, Scan]:
        return check_png_slices(path, keep_layers, labels)

    def run_output(self, run: RunDir, mixture: bool = False) -> Path:
        return run.slices_path

    def describe(self, summary: dict) -> str:
        return slices_line(summary, summary["layer_thickness_um"])
