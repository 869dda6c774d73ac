"""Printer profiles: how many model materials a job may use, the resolutions a machine prints and the vendor's
name of the material loaded for each inkopt ink.

Where the figures come from (say so for every new entry; check your machine's configuration before printing):

- Voxel printing on Stratasys PolyJet (GrabCAD Voxel Print) takes 600 x 300 DPI slices of 27 um: the GCVF
  configuration written by OpenVCAD (``GCVFExporter``: ``m_x_dpi = 600``, ``m_y_dpi = 300``,
  ``m_slice_thickness_nm = 27000``; C++ API docs, matterassembly.org/OpenVCAD-Docs/v2/cpp-api/
  libvcad-compilers-inkjet.html) and its material-inkjet guide ("J750-style voxel pitch 0.0423 x 0.0846 x
  0.027 mm"). Stratasys's "PolyJet Multi-Color design guideline" (GrabCAD tutorials) gives 27 um layers.
- Material slots: the Stratasys spec sheets (J750: six model materials loaded at once plus support; J850:
  seven plus support; J55 Prime: five) and Mimaki's 3DUJ-553 brochure (C, M, Y, K, white and clear plus
  support). These we know from the vendors' public spec sheets but could not re-check against a stored copy;
  neither could we the 14 um (J750/J850 high-quality mode) and 18.75 um (J55) layers. The Mimaki has no DPI
  here: we found no public figure for its voxel grid, so resolutions are not checked for it.
- Material names: the names GrabCAD Print's voxel packages carry in ``ConfigFile.xml`` (``<Material><Name>``).
  A public GCVF builder (jackcrane/pj-voxelprint-colorwheels-v3, ``4/buildGCVF.js``) names cyan, magenta, yellow
  and white ``VeroCY-V``, ``VeroMGT-V``, ``VeroYL-V``, ``VUltraWhite``; OpenVCAD's pyvcad examples
  (``GCVFCompiler`` with a ``channel_material_map``) name black ``VeroBlack``, clear ``VeroClear`` and white
  ``VeroPureWht``. The two white names are two materials (VeroUltraWhite, VeroPureWhite); the profiles take the
  builder's, whose packages were made for a real job, and ``--material white=VeroPureWht`` overrides it per ink.
  An ink without a vendor material (orange, cyan2, ...) maps to None: load a material of your choice and map its
  colour in the printer's software.
- ``gcvf_colors``: the ``MaxNumberOfColors`` of a GCVF package. The builder writes 6 for every job; no source says
  whether GrabCAD Print expects the machine's slot count there (7 on a J850), so it is a profile setting, 6 for
  every Stratasys profile.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import ParameterError
from ..units import dpi_of

# inkopt ink name -> GrabCAD material name of the Stratasys material loaded for it (module docstring)
_VERO = {
    "cyan": "VeroCY-V",
    "magenta": "VeroMGT-V",
    "yellow": "VeroYL-V",
    "black": "VeroBlack",
    "white": "VUltraWhite",
    "transparent": "VeroClear",
    "clear": "VeroClear",
}


@dataclass(frozen=True)
class PrinterProfile:
    """What a printer takes: ``key`` (its name in ``PRINTER_PROFILES``), ``name`` (for people), ``max_materials``
    model materials per job (None: no limit), ``dpi`` (x, y) of its voxel grid and ``layer_um`` its layer
    thicknesses in µm (None and () where no public figure is known: not checked), ``materials`` the vendor
    material loaded for each inkopt ink name, ``gcvf_colors`` the ``MaxNumberOfColors`` its GCVF packages carry
    (None: its material limit)."""

    key: str
    name: str
    max_materials: int | None
    dpi: tuple[int, int] | None = None
    layer_um: tuple[float, ...] = ()
    materials: dict = field(default_factory=dict)
    gcvf_colors: int | None = None

    def material(self, ink: str) -> str | None:
        """The vendor material loaded for ``ink`` (case-insensitive), or None if unknown."""
        return self.materials.get(str(ink).lower())

    def to_json(self) -> dict:
        """The profile as a JSON object; ``dpi`` and ``layer_um`` only where known."""
        d = {"key": self.key, "name": self.name, "max_materials": self.max_materials}
        if self.dpi is not None:
            d["dpi"] = list(self.dpi)
        if self.layer_um:
            d["layer_um"] = list(self.layer_um)
        d["materials"] = dict(self.materials)
        if self.gcvf_colors is not None:
            d["gcvf_colors"] = self.gcvf_colors
        return d

    @classmethod
    def from_json(cls, d: dict) -> PrinterProfile:
        dpi = d.get("dpi")
        return cls(
            d["key"],
            d["name"],
            d.get("max_materials"),
            None if dpi is None else tuple(dpi),
            tuple(d.get("layer_um", ())),
            dict(d.get("materials", {})),
            d.get("gcvf_colors"),
        )


PRINTER_PROFILES: dict[str, PrinterProfile] = {
    p.key: p
    for p in (
        # six colour materials at once + support (Stratasys J750 spec sheet); 27 um voxel-print layers, 14 um HQ
        PrinterProfile(
            "j750",
            "Stratasys J750",
            6,
            (600, 300),
            (27.0, 14.0),
            _VERO,
            6,
        ),
        # seven materials at once + support (Stratasys J850 spec sheet); same voxel grid as the J750
        PrinterProfile(
            "j850",
            "Stratasys J850",
            7,
            (600, 300),
            (27.0, 14.0),
            _VERO,
            6,
        ),
        # five materials + support, 18.75 um layers (Stratasys J55 Prime spec sheet; not re-checked)
        PrinterProfile(
            "j55",
            "Stratasys J55 Prime",
            5,
            (600, 300),
            (18.75,),
            _VERO,
            6,
        ),
        # C, M, Y, K, white, clear + support (Mimaki 3DUJ-553 brochure); no public voxel grid or ink names found
        PrinterProfile("mimaki-3duj-553", "Mimaki 3DUJ-553", 6),
        PrinterProfile("generic", "no material limit", None),
    )
}


def printer_profile(name: str) -> PrinterProfile:
    """The profile ``name`` (case-insensitive); a one-line ValueError names the known ones."""
    key = str(name).strip().lower()
    if key not in PRINTER_PROFILES:
        raise ValueError(f"unknown printer '{name}'; use one of {list(PRINTER_PROFILES)}")
    return PRINTER_PROFILES[key]


def material_name(profile: PrinterProfile | None, ink: str) -> str | None:
    """The vendor material ``profile`` loads for ``ink`` (case-insensitive), or None if unknown."""
    return None if profile is None else profile.material(ink)


def check_slots(used: list[str], limit: int | None, printer: str | None = None) -> None:
    """A one-line ``ParameterError`` when a job uses more inks (``used``, their names) than ``limit`` materials
    (None: no limit) of the printer named ``printer``."""
    if limit is None or len(used) <= limit:
        return
    who = printer or "the printer"
    raise ParameterError(
        f"the print uses {len(used)} inks ({', '.join(used)}) but {who} holds {limit} materials per job; "
        f"use an ink set of at most {limit} inks or a printer with more material slots (`printer`)"
    )


def resolution_mismatch(profile: PrinterProfile, voxel_mm_printer) -> str | None:
    """Why a printer grid of ``voxel_mm_printer`` (x, y, z) mm does not match what ``profile`` prints (its DPI in
    x and y, one of its layer thicknesses), or None if it does or the profile does not say."""
    if profile.dpi is None:
        return None
    vp = np.asarray(voxel_mm_printer, np.float64)
    dpi = dpi_of(vp[:2])
    layer_ok = any(abs(vp[2] * 1000 - t) < 0.05 for t in profile.layer_um or (vp[2] * 1000,))
    if np.allclose(dpi, profile.dpi, rtol=1e-3) and layer_ok:
        return None
    return (
        f"the slices are {dpi[0]:.0f} x {dpi[1]:.0f} DPI with {vp[2] * 1000:.1f} um layers; {profile.name} "
        f"prints {profile.dpi[0]} x {profile.dpi[1]} DPI with "
        f"{' or '.join(f'{t:g}' for t in profile.layer_um)} um layers"
    )
