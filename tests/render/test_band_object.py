"""A band volume as a Ray worker is sent it (``shardwire.BandObject``): the inside mask's runs round-trip exactly,
a renderer built from it renders and differentiates bit-identically to one built from the volume, and it carries
no grid-sized array."""

import numpy as np
import pytest
from helpers import fuzz
from hypothesis import example, given
from hypothesis import strategies as st

from inkopt.model import Band, InkTable, Volume
from inkopt.render import Renderer
from inkopt.shardwire import BandObject, payload_bytes

pytest.importorskip("inkopt._core")

INKS = InkTable.parse("vero-cmykw")


def band_volume(inside: np.ndarray, seed: int = 0, form: str = "labels") -> Volume:
    """A volume of ``inside`` whose band is a random half of its inside voxels, the core white."""
    rng = np.random.default_rng(seed)
    flat = np.flatnonzero(inside)
    band = Band(np.sort(rng.choice(flat, len(flat) // 2, replace=False)), np.eye(5, dtype=np.float32)[4])
    common = dict(inside=inside, band=band, boundary="box")
    if form == "labels":
        labels = np.where(inside, rng.integers(0, 5, inside.shape), 255).astype(np.uint8)
        return Volume.from_labels((0.1, 0.1, 0.1), labels, INKS, **common)
    mixture = rng.dirichlet(np.ones(5), inside.shape).astype(np.float32)
    return Volume.from_mixture((0.1, 0.1, 0.1), mixture, INKS, **common)


@st.composite
def masks(draw):
    shape = tuple(draw(st.integers(1, 9)) for _ in range(3))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    return rng.random(shape) < draw(st.sampled_from([0.0, 0.2, 0.6, 1.0]))


@fuzz(150)
@given(masks(), st.integers(1, 400))
@example(np.ones((3, 4, 5), bool), 20)  # every voxel inside: each row's run ends where the next row's begins
@example(np.zeros((2, 3, 4), bool), 7)  # nothing inside
def test_runs_round_trip(inside, slab):
    """The mask made from the runs equals the volume's, whatever the slab size the runs were read in."""
    if not inside.any():
        inside = inside.copy()
        inside.reshape(-1)[0] = True  # a band needs an inside voxel to lie in
    obj = BandObject.of(band_volume(inside), slab=slab)
    np.testing.assert_array_equal(obj.inside_bytes().view(bool), inside)
    assert np.all(obj.starts < obj.ends) and np.all(obj.ends[:-1] <= obj.starts[1:])


@pytest.mark.parametrize("form", ["labels", "mixture"])
def test_renderer_from_band_object_is_bit_identical(form):
    """A renderer built from the band object (a ball with a random band) renders and differentiates exactly as one
    built from the volume, before and after ``set_mixture``; besides the band's index it carries fewer bytes than
    the volume (whose inside mask is a bit per voxel and whose medium a byte or more per voxel; the object's runs and
    band medium grow with the surface, not the grid)."""
    z, y, x = np.mgrid[:14, :16, :18]
    inside = (z - 6.5) ** 2 + (y - 7.5) ** 2 + (x - 8.5) ** 2 < 36
    vol = band_volume(inside, 1, form)
    obj = BandObject.of(vol)
    from inkopt.model import Texels

    tex = Texels.exposed_faces(inside)
    adj = np.random.default_rng(2).normal(size=(len(tex), 3)).astype(np.float32)
    a, b = Renderer(vol, threads=2), Renderer(obj, threads=2)
    for step in range(2):
        np.testing.assert_array_equal(a.render(tex, 2, 5).rgb, b.render(tex, 2, 5).rgb)
        ga, gb = (
            a.gradient(tex, adj, 2, 6, grad_index=vol.band.index),
            b.gradient(tex, adj, 2, 6, grad_index=vol.band.index),
        )
        np.testing.assert_array_equal(ga[0], gb[0])
        np.testing.assert_array_equal(ga[1], gb[1])
        assert np.abs(ga[1]).max() > 0
        rows = np.random.default_rng(step).dirichlet(np.ones(5), len(vol.band.index)).astype(np.float32)
        a.set_mixture(vol.band.index, rows)
        b.set_mixture(vol.band.index, rows)
    rest = payload_bytes(vol.band)  # the band's index, sent either way
    assert payload_bytes(vol.inside) == vol.inside.bits.nbytes
    assert payload_bytes(obj) - rest < payload_bytes(vol) - rest


def test_volume_without_a_band_does_not_fit():
    inside = np.ones((2, 3, 4), bool)
    vol = Volume.from_labels((0.1, 0.1, 0.1), np.zeros((2, 3, 4), np.uint8), INKS, inside=inside)
    assert not BandObject.fits(vol) and BandObject.fits(band_volume(inside))
