"""How the RGB core sees a spectral ink table's bands: a group of 1-3 bands as an RGB-shaped ink table, a volume
read with it, and the checks a band render makes of its groups and its lighting."""

from __future__ import annotations

import numpy as np

from ..errors import ParameterError
from ..lighting import Lighting
from ..model import InkTable, Labels, Mixture, Volume
from ..model.spectral import GROUP, SpectralInkTable


def with_inks(volume: Volume, inks: InkTable) -> Volume:
    """``volume`` with its mixture or labels read with another ink table of the same inks (a band group)."""
    med = volume.medium
    if isinstance(med, Mixture):
        return volume.with_medium(Mixture(med.mixture, inks))
    if isinstance(med, Labels):
        return volume.with_medium(Labels(med.labels, inks))
    raise ParameterError("`volume` must hold a mixture or labels to be rendered with a spectral ink table")


def check_groups(groups, bands: int) -> None:
    """A ParameterError naming `groups` unless they split the bands 0..bands-1 into groups of 1-3 bands."""
    flat = [b for g in groups for b in g]
    if sorted(flat) != list(range(bands)) or not all(1 <= len(g) <= GROUP for g in groups):
        raise ParameterError(f"`groups` must hold each of the {bands} bands once, at most {GROUP} per group")


def band_table(table: SpectralInkTable, bands) -> InkTable:
    """The RGB-shaped table of a group of 1-3 ``bands`` of ``table``: its channels the bands in order, a short
    group's last band repeated to fill three channels (as ``SpectralInkTable.band_groups`` makes them)."""
    pick = list(bands) + [bands[-1]] * (GROUP - len(bands))
    return InkTable(table.names, table.sigma_s[:, pick], table.sigma_a[:, pick], table.g)


def check_grey(lighting: Lighting) -> Lighting:
    """``lighting`` if its radiance is the same in R, G and B; a ParameterError naming `lighting` otherwise."""
    env = lighting.map
    if env is not None and not (np.array_equal(env[..., 0], env[..., 1]) and np.array_equal(env[..., 0], env[..., 2])):
        raise ParameterError(
            "`lighting` must be grey (equal R, G, B) with a spectral ink table: the light's spectrum is the illuminant"
        )
    return lighting
