"""The ink tables of a run from ``--inks``: the scene's RGB table and, for a spectral table, the spectral one.

A scene's volume and its print-shop baselines (``evaluation.baselines``) are built from an RGB ink table; a
spectral run renders its bands from the spectral table (``spectral.viewing.Viewing``). For the library's spectral
form (``<preset>@spectral``) the RGB table is the library's own; for a spectral ink file it is the table's RGB
stand-in (:func:`rgb_stand_in`), which only those baselines' colour tables see.
"""

from __future__ import annotations

from ..model import InkTable
from ..model.spectral import SPECTRAL_SUFFIXES, SpectralInkTable, load_ink_table, rgb_basis


def rgb_stand_in(table: SpectralInkTable) -> InkTable:
    """An RGB table of ``table``'s inks: per ink, σs and σa of channel c are the band values averaged with the
    weights of the Mallett & Yuksel (2019) sRGB basis b_c(λ) (``model.spectral.rgb_basis``), in mm^-1. A flat
    spectrum gives equal channels; it inverts ``SpectralInkTable.from_rgb`` only approximately."""
    basis = rgb_basis(table.wavelengths_nm)  # (3, B)
    weights = basis / basis.sum(axis=1, keepdims=True)
    return InkTable(table.names, table.sigma_s @ weights.T, table.sigma_a @ weights.T, table.g)


def run_inks(spec: str) -> tuple[InkTable, SpectralInkTable | None]:
    """(the scene's RGB table, the spectral table or None) of an ink spec (``model.spectral.load_ink_table``:
    a preset, a list of library inks, an ink file, ``<preset>@spectral``)."""
    table = load_ink_table(spec)
    if isinstance(table, InkTable):
        return table, None
    base, at, suffix = str(spec).rpartition("@")
    if at and suffix.lower() in SPECTRAL_SUFFIXES:
        return InkTable.parse(base), table
    return rgb_stand_in(table), table


def is_spectral(spec: str) -> bool:
    """Whether an ink spec names a spectral table (loading it, so a bad spec fails here as it would anywhere)."""
    return not isinstance(load_ink_table(spec), InkTable)
