"""The calibration chart: its patches, their CGATS.17 columns, the design of a chart for an ink set and the check
that a chart can identify every parameter.

Columns (docs/calibration.md): ``SAMPLE_ID``, one share column ``INK_<NAME>`` per ink (shares sum to 1),
``THICKNESS_MM`` of the patch layer, ``BACKING`` ("none" or an ink name, usually "white"), ``BACKING_MM`` (the
backing layer's thickness; 0 with "none"), then the measurement columns (``LAB_L LAB_A LAB_B`` or
``SPECTRAL_NM380 ... SPECTRAL_NM730``, ``calibration.measure``).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import numpy as np

from ..errors import ParameterError
from ..model import InkTable
from .cgats import CgatsError, CgatsTable
from .stack import Stack

SHARE_TOLERANCE = 1e-3  # shares must sum to 1 within this
WHITE = "white"
NONE = "none"
# The designed chart (thicknesses in mm, multiples of 0.1 mm so that every stack sits on a 0.1 mm grid).
OVER_WHITE_MM = (0.1, 0.2, 0.4, 0.7, 1.0, 1.5)
ALONE_MM = (0.3, 0.7, 1.5)
WHITE_ALONE_MM = (0.3, 0.6, 1.0, 1.5, 2.5, 4.0)
DILUTIONS = (0.5, 0.25, 0.1, 0.04)
BACKING_MM = 2.0
MIX_MM = 1.0


class ChartError(ParameterError):
    """A chart that cannot be read or cannot identify the inks' parameters (one line)."""


@dataclass(frozen=True)
class Patch:
    """One patch: ``shares`` (N,) of the chart's inks, the patch layer's ``thickness_mm``, ``backing`` ("none" or
    an ink name) and its ``backing_mm``."""

    sample_id: str
    shares: tuple[float, ...]
    thickness_mm: float
    backing: str
    backing_mm: float

    def stack(self, names: tuple[str, ...]) -> Stack:
        """The patch's :class:`Stack` over an ink table whose inks are the chart's, ``names``, in that order."""
        b = None if self.backing == NONE else names.index(self.backing)
        return Stack(tuple(self.shares), float(self.thickness_mm), b, float(self.backing_mm) if b is not None else 0.0)

    def pure_ink(self) -> int | None:
        """The index of the ink that makes up the whole patch layer, or None for a mixture."""
        s = np.asarray(self.shares)
        i = int(np.argmax(s))
        return i if s[i] > 1.0 - SHARE_TOLERANCE else None

    def describe(self, names) -> str:
        layer = "+".join(f"{s:g} {n}" for s, n in zip(self.shares, names) if s > 0)
        under = "nothing" if self.backing == NONE else f"{self.backing_mm:g} mm {self.backing}"
        return f"{layer}, {self.thickness_mm:g} mm over {under}"


@dataclass
class Chart:
    """The chart's ink names (lower case, column order) and its patches."""

    inks: tuple[str, ...]
    patches: list[Patch]

    def __len__(self) -> int:
        return len(self.patches)

    def subset(self, index) -> Chart:
        return Chart(self.inks, [self.patches[i] for i in index])

    def stacks(self) -> list[Stack]:
        return [p.stack(self.inks) for p in self.patches]

    def table(self, measurement_fields=("LAB_L", "LAB_A", "LAB_B"), header: dict | None = None) -> CgatsTable:
        """The chart as a CGATS table with the measurement columns empty."""
        fields = ["SAMPLE_ID", *(f"INK_{n.upper()}" for n in self.inks), "THICKNESS_MM", "BACKING", "BACKING_MM"]
        rows = [
            [
                int(p.sample_id) if p.sample_id.isdigit() else p.sample_id,
                *(float(s) for s in p.shares),
                float(p.thickness_mm),
                p.backing,
                float(p.backing_mm),
            ]
            + [""] * len(measurement_fields)
            for p in self.patches
        ]
        return CgatsTable(fields + list(measurement_fields), rows, dict(header or {}))


def _num(v: str, what: str) -> float:
    try:
        x = float(v)
    except ValueError:
        raise ChartError(f"{what} is '{v}', not a number") from None
    if not np.isfinite(x):
        raise ChartError(f"{what} is {v}")
    return x


def chart_from_table(table: CgatsTable, where: str = "chart") -> Chart:
    """The chart columns of a CGATS table (ink names from the ``INK_<NAME>`` fields); :class:`ChartError` for a
    missing column, a share outside [0, 1], shares not summing to 1, a bad thickness or backing."""
    from .cgats import canonical_field

    canon = [canonical_field(f) for f in table.fields]
    missing = [c for c in ("SAMPLE_ID", "THICKNESS_MM", "BACKING", "BACKING_MM") if c not in canon]
    if missing:
        raise ChartError(f"{where}: missing column(s) {', '.join(missing)}")
    ink_cols = [(i, c[4:].lower()) for i, c in enumerate(canon) if c.startswith("INK_") and len(c) > 4]
    if not ink_cols:
        raise ChartError(f"{where}: no ink share column (INK_<NAME>)")
    names = tuple(n for _, n in ink_cols)
    if len(set(names)) != len(names):
        raise ChartError(f"{where}: an ink share column appears twice")
    col = {c: canon.index(c) for c in ("SAMPLE_ID", "THICKNESS_MM", "BACKING", "BACKING_MM")}
    patches, seen = [], set()
    for row in table.rows:
        sid = row[col["SAMPLE_ID"]]
        at = f"{where}: patch {sid}"
        if sid in seen:
            raise ChartError(f"{where}: SAMPLE_ID {sid} appears twice")
        seen.add(sid)
        shares = np.array([_num(row[i], f"{at} INK_{n.upper()}") for i, n in ink_cols])
        if np.any(shares < 0) or np.any(shares > 1):
            raise ChartError(f"{at}: ink shares must lie in [0, 1], got {shares.tolist()}")
        if abs(shares.sum() - 1.0) > SHARE_TOLERANCE:
            raise ChartError(f"{at}: ink shares sum to {shares.sum():.4g}, not 1")
        thick = _num(row[col["THICKNESS_MM"]], f"{at} THICKNESS_MM")
        if not 0 < thick <= 100:
            raise ChartError(f"{at}: THICKNESS_MM must lie in (0, 100] mm, got {thick:g}")
        backing = row[col["BACKING"]].strip().lower()
        bmm = _num(row[col["BACKING_MM"]], f"{at} BACKING_MM")
        if backing == NONE:
            if bmm != 0:
                raise ChartError(f"{at}: BACKING_MM must be 0 with BACKING none, got {bmm:g}")
        elif backing not in names:
            raise ChartError(f"{at}: BACKING '{backing}' is neither 'none' nor one of the chart's inks {list(names)}")
        elif not 0 < bmm <= 100:
            raise ChartError(f"{at}: BACKING_MM must lie in (0, 100] mm, got {bmm:g}")
        patches.append(Patch(sid, tuple(float(s) for s in shares / shares.sum()), thick, backing, bmm))
    if not patches:
        raise ChartError(f"{where}: the table has no patches")
    return Chart(names, patches)


def check_identifiable(chart: Chart) -> None:
    """Every ink of the chart must appear pure in at least two patches that differ in thickness or backing (one
    reflectance per channel cannot tell its scattering from its absorption), as a patch layer or as a backing.
    :class:`ChartError` names the first ink that does not and what is missing."""
    configs: dict[str, set] = {n: set() for n in chart.inks}
    for p in chart.patches:
        k = p.pure_ink()
        if k is not None:
            configs[chart.inks[k]].add((round(p.thickness_mm, 6), p.backing, round(p.backing_mm, 6)))
    for n in chart.inks:
        c = configs[n]
        if not c:
            raise ChartError(f"ink '{n}': no patch of the pure ink; its scattering and absorption cannot be fitted")
        if len(c) < 2:
            ((t, b, bmm),) = c
            under = "nothing" if b == NONE else f"{bmm:g} mm {b}"
            raise ChartError(
                f"ink '{n}': only one pure patch ({t:g} mm over {under}); add another thickness or backing to "
                "tell its scattering from its absorption"
            )


def design_chart(names, white: str = WHITE) -> Chart:
    """The patch set of ``inkopt calibration-chart`` for the inks ``names`` (one of them ``white``): each other ink
    pure over 2 mm of white at six thicknesses and alone (nothing under it) at three, diluted in white at four
    shares; white alone at six thicknesses; then checks: every pair of colour inks 1:1, 3:1, 1:3 and 1:1:1 with
    white, every triple 1:1:1 and all colour inks in equal shares (1 mm over white). Sample ids are 1, 2, ..."""
    names = tuple(n.strip().lower() for n in names)
    if white not in names:
        raise ChartError(f"the chart needs the printer's white ink ('{white}') as backing; inks are {list(names)}")
    w = names.index(white)
    colours = [i for i in range(len(names)) if i != w]
    rows: list[tuple[np.ndarray, float, str, float]] = []

    def share(**idx):
        s = np.zeros(len(names))
        for i, v in idx.items():
            s[int(i)] += v
        return s

    for i in colours:
        rows += [(share(**{str(i): 1.0}), t, white, BACKING_MM) for t in OVER_WHITE_MM]
        rows += [(share(**{str(i): 1.0}), t, NONE, 0.0) for t in ALONE_MM]
        rows += [(share(**{str(i): d, str(w): 1 - d}), MIX_MM, white, BACKING_MM) for d in DILUTIONS]
    rows += [(share(**{str(w): 1.0}), t, NONE, 0.0) for t in WHITE_ALONE_MM]
    for i, j in combinations(colours, 2):
        for a in (0.5, 0.75, 0.25):
            rows.append((share(**{str(i): a, str(j): 1 - a}), MIX_MM, white, BACKING_MM))
        rows.append((share(**{str(i): 1 / 3, str(j): 1 / 3, str(w): 1 / 3}), MIX_MM, white, BACKING_MM))
    for tri in combinations(colours, 3):
        rows.append((share(**{str(k): 1 / 3 for k in tri}), MIX_MM, white, BACKING_MM))
    if len(colours) > 3:
        rows.append((share(**{str(k): 1 / len(colours) for k in colours}), MIX_MM, white, BACKING_MM))
    patches = [
        Patch(str(k + 1), tuple(float(round(v, 6)) for v in s), float(t), b, float(bmm))
        for k, (s, t, b, bmm) in enumerate(rows)
    ]
    chart = Chart(names, patches)
    check_identifiable(chart)
    return chart


def start_table(chart: Chart, start: InkTable) -> InkTable:
    """The starting ink table in the chart's ink order: each chart ink from ``start``, else from the ink library;
    :class:`ChartError` for an ink in neither."""
    from ..model.inks import INK_LIBRARY

    mu_t, albedo = [], []
    for n in chart.inks:
        if n in start.names:
            k = start.names.index(n)
            mu_t.append(start.mu_t[k])
            albedo.append(start.albedo[k])
        elif n in INK_LIBRARY:
            mu_t.append(INK_LIBRARY[n][0])
            albedo.append(INK_LIBRARY[n][1])
        else:
            raise ChartError(
                f"unknown ink '{n}' in the chart: not in the starting ink table {list(start.names)} nor in "
                "the ink library; give `start` an ink file that has it"
            )
    return InkTable.from_mu_t_albedo(chart.inks, mu_t, albedo, start.g)


__all__ = ["CgatsError", "Chart", "ChartError", "Patch", "chart_from_table", "check_identifiable", "design_chart"]
