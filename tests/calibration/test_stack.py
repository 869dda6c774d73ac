"""The measurement model: adding-doubling of a two-layer stack (``calibration.stack``) against inkopt's Monte
Carlo renderer of the same stack under light from the upper hemisphere, within the renderer's standard error
(plus adding-doubling's own discretisation error, its 16- against 32-point quadrature), and the one-layer case
against iadpython's own single-slab routine."""

import numpy as np
import pytest

from inkopt.calibration.stack import Stack, channel_reflectance, reflectance_ad, reflectance_mc, stack_volume
from inkopt.model import InkTable

iad = pytest.importorskip("iadpython")
INKS = InkTable.parse("vero-cmykw")


@pytest.mark.parametrize(
    "stack",
    [
        Stack((1, 0, 0, 0, 0), 0.3, 4, 2.0),  # cyan over white
        Stack((0, 0, 0, 1, 0), 0.2, 4, 1.0),  # black over white: mostly specular and absorption
        Stack((0, 0, 0, 0, 1), 1.0, None, 0.0),  # white alone
        Stack((0, 0.5, 0.25, 0, 0.25), 0.7, 0, 0.5),  # a mixture over cyan
    ],
    ids=["cyan-on-white", "black-on-white", "white-alone", "mixture-on-cyan"],
)
def test_adding_doubling_matches_the_renderer(stack):
    """Four standard errors of the mean (a false alarm ~6e-5 per channel) plus |R16 - R32|."""
    mc, se = reflectance_mc(stack, INKS, spp=200_000, seed=11)
    ad16, ad32 = reflectance_ad(stack, INKS, quad_pts=16), reflectance_ad(stack, INKS, quad_pts=32)
    tol = 4 * se + np.abs(ad16 - ad32)
    assert np.all(np.abs(mc - ad32) < tol), (mc, ad32, tol)


def test_one_layer_is_iadpythons_slab():
    r = iad.Sample(a=0.9, b=2.0, g=0.4, d=1.0, n=1.5, quad_pts=16).rt()[0]
    assert channel_reflectance([(1.8, 0.2, 1.0)], 0.4) == pytest.approx(r, rel=1e-12)
    # Splitting a layer in two identical halves changes nothing (the adding step).
    assert channel_reflectance([(1.8, 0.2, 0.5), (1.8, 0.2, 0.5)], 0.4) == pytest.approx(r, rel=1e-9)


def test_stack_volume_layers():
    vol = stack_volume(Stack((0, 1, 0, 0, 0), 0.3, 4, 2.0), INKS)
    assert vol.shape[1:] == (1, 1) and vol.boundary == "periodic-xy"
    nz = vol.shape[0]
    top = int(round(0.3 / vol.voxel_mm[2]))
    np.testing.assert_allclose(vol.sigma_s[nz - top :, 0, 0], np.broadcast_to(INKS.sigma_s[1], (top, 3)), rtol=1e-6)
    np.testing.assert_allclose(
        vol.sigma_s[: nz - top, 0, 0], np.broadcast_to(INKS.sigma_s[4], (nz - top, 3)), rtol=1e-6
    )
    assert nz * vol.voxel_mm[2] == pytest.approx(2.3)
