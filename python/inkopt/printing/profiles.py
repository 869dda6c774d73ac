"""Printer profiles: how many model materials a job may use, and the resolutions a machine prints.

Model-material slots per job (support material not counted) are from the vendors' spec sheets; check your
machine's configuration. A new printer is one entry here.
"""
from __future__ import annotations

import numpy as np

from ..units import dpi_of

PRINTER_PROFILES: dict[str, dict] = {
    "j750": {"name": "Stratasys J750", "max_materials": 6, "dpi": (600, 300), "layer_um": (27.0, 14.0)},
    "j850": {"name": "Stratasys J850", "max_materials": 7, "dpi": (600, 300), "layer_um": (27.0, 14.0)},
    "j55": {"name": "Stratasys J55 Prime", "max_materials": 5, "dpi": (600, 300), "layer_um": (18.75,)},
    "mimaki-3duj-553": {"name": "Mimaki 3DUJ-553 (C, M, Y, K, W, clear)", "max_materials": 6},
    "generic": {"name": "no material limit", "max_materials": None},
}


def printer_profile(name: str) -> dict:
    """The profile ``name`` (case-insensitive); a one-line ValueError names the known ones."""
    key = str(name).strip().lower()
    if key not in PRINTER_PROFILES:
        raise ValueError(f"unknown printer '{name}'; use one of {list(PRINTER_PROFILES)}")
    return PRINTER_PROFILES[key]


def resolve_max_materials(max_materials) -> int | None:
    """An int limit, a ``PRINTER_PROFILES`` key (its limit), or None (no limit)."""
    if max_materials is None:
        return None
    if isinstance(max_materials, str):
        key = max_materials.strip().lower()
        if key not in PRINTER_PROFILES:
            raise ValueError(f"unknown printer profile '{max_materials}'; use one of {list(PRINTER_PROFILES)}")
        return PRINTER_PROFILES[key]["max_materials"]
    n = int(max_materials)
    if n < 1:
        raise ValueError(f"max_materials must be at least 1, got {max_materials}")
    return n


def resolution_mismatch(profile: dict, voxel_mm_printer) -> str | None:
    """Why a printer grid of ``voxel_mm_printer`` (x, y, z) mm does not match what ``profile`` prints (its DPI in
    x and y, one of its layer thicknesses), or None if it does or the profile does not say."""
    if "dpi" not in profile:
        return None
    vp = np.asarray(voxel_mm_printer, np.float64)
    dpi = dpi_of(vp[:2])
    layer_ok = any(abs(vp[2] * 1000 - t) < 0.05 for t in profile.get("layer_um", (vp[2] * 1000,)))
    if np.allclose(dpi, profile["dpi"], rtol=1e-3) and layer_ok:
        return None
    return (f"the slices are {dpi[0]:.0f} x {dpi[1]:.0f} DPI with {vp[2] * 1000:.1f} um layers; {profile['name']} "
            f"prints {profile['dpi'][0]} x {profile['dpi'][1]} DPI with "
            f"{' or '.join(f'{t:g}' for t in profile['layer_um'])} um layers")
