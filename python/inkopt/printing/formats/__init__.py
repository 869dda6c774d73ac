"""Printer output formats: one module per format, each with its writer and its checker, and one registry.

- ``png_slices``: one RGBA PNG per layer plus ``manifest.json`` (any voxel-printing workflow);
- ``gcvf``: the GrabCAD Voxel Print package (Stratasys PolyJet);
- ``threemf``: a 3MF with the Volumetric extension, of the continuous mixture or of the labels.

Every writer takes one ``job.PrintJob`` (the voxels, printer profile, material names, palette and provenance) and
an output path; every checker reads a package back one layer at a time (``inspection``). What they share lives
once: ink colours and slice images (``slices``), the outline mesh (``outline``), zip targets (``archive``), zip
member names and reads within a bound (``members``).
``FORMATS`` maps each format's name to its ``Format``; a new format is one module with a ``Format`` class and
one line here (and its default output file in ``rundir.RunDir``).
"""

from __future__ import annotations

import zipfile
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from .gcvf import Gcvf
from .inspection import PackageError, PackageReport, Scan
from .png_slices import PngSlices
from .threemf import ThreeMF

if TYPE_CHECKING:
    from ...rundir import RunDir
    from .job import PrintJob


class Format(Protocol):
    """A printer output format. ``name``: its ``--format`` value and report kind; ``suffix``: its file suffix
    ("" for a folder); ``default_printer``: the printer profile key the command line assumes; ``takes_mixture``:
    whether it also writes a continuous mixture (``job.MixtureVoxels``), not only labels."""

    name: str
    suffix: str
    default_printer: str
    takes_mixture: bool

    def write(self, job: PrintJob, path) -> dict:
        """Write ``job`` to ``path`` (atomically; a foreign file or folder there is refused); a summary dict."""
        ...

    def recognises(self, path: Path) -> bool:
        """Whether ``path`` (an existing file or folder) is a package of this format, by its contents."""
        ...

    def check(self, path: Path, keep_layers=(), labels: bool = False) -> tuple[PackageReport, Scan]:
        """Read ``path`` back and check that its parts agree (``inspection``); ``PackageError`` otherwise."""
        ...

    def run_output(self, run: RunDir, mixture: bool = False) -> Path:
        """Where a run directory keeps this format's output (of the mixture with ``mixture``)."""
        ...

    def describe(self, summary: dict) -> str:
        """One line on a written package, from the summary ``write`` returned."""
        ...


FORMATS: dict[str, Format] = {f.name: f for f in (PngSlices(), Gcvf(), ThreeMF())}


def format_named(name: str) -> Format:
    """The format called ``name``; a one-line ValueError names the known ones."""
    if name not in FORMATS:
        raise ValueError(f"unknown export format '{name}'; use one of {list(FORMATS)}")
    return FORMATS[name]


def format_of(path) -> Format:
    """The format of the package at ``path``, told by its contents, else a zip by its suffix (whose checker then
    names what it lacks); a PackageError if none."""
    path = Path(path)
    if not path.exists():
        raise PackageError(f"{path} does not exist")
    for fmt in FORMATS.values():
        if fmt.recognises(path):
            return fmt
    named = [f for f in FORMATS.values() if f.suffix and f.suffix == path.suffix.lower()]
    if named and zipfile.is_zipfile(path):  # a zip named as a format's: its checker names the part it lacks
        return named[0]
    raise PackageError(f"{path} is no printer package inkopt reads ({', '.join(FORMATS)})")


def inspect_package(path, *, keep_layers=(), labels: bool = False) -> tuple[PackageReport, Scan]:
    """Read and check the package ``path`` of any format (``Format.check``). Returns ``(PackageReport, Scan)``;
    the scan holds ``top`` / ``top_label`` ((Y, X) in image rows), ``kept`` {layer: (Y, X) labels in image rows}
    for ``keep_layers`` (layer indices, or a count of evenly spaced layers) and, with ``labels``, ``labels``
    (Z, Y, X) uint8 in the writers' frame (3MF: each printed voxel's largest share)."""
    return format_of(path).check(Path(path), keep_layers, labels)
