"""The volume model: explicit medium forms, typed optional fields, the .npz round trip, one-line errors."""
import numpy as np
import pytest

from inkopt.model import Dense, InkTable, Labels, Mixture, Quantization, Volume, VolumeError

INKS = InkTable.parse("vero-cmykw")
VOX = (0.0847, 0.0847, 0.0847)


def _mixture(shape=(3, 4, 5), seed=0):
    return np.random.default_rng(seed).dirichlet(np.ones(len(INKS)), size=shape).astype(np.float32)


def test_keyword_and_typed_construction_agree():
    m = _mixture()
    a = Volume(VOX, mixture=m, inks=INKS)
    b = Volume(VOX, medium=Mixture(m, INKS))
    assert isinstance(a.medium, Mixture) and a.form == b.form == "mixture" and a.shape == (3, 4, 5)
    np.testing.assert_array_equal(a.mixture, b.mixture)
    assert a.inks is INKS and a.labels is None and a.sigma_s is None


@pytest.mark.parametrize("form", ["dense", "mixture", "labels"])
def test_file_round_trip_keeps_form_and_typed_fields(tmp_path, form):
    m = _mixture()
    if form == "dense":
        med = Dense(*Volume(VOX, mixture=m, inks=INKS).coefficients())
    elif form == "mixture":
        med = Mixture(m, INKS)
    else:
        med = Labels(np.argmax(m, -1).astype(np.uint8), INKS)
    q = Quantization("random", 5, (600.0, 300.0, 940.7), "linear") if form == "labels" else None
    v = Volume(VOX, medium=med, origin_mm=(1.0, -2.0, 0.5), quantization=q, boundary="periodic-xy", g=0.3)
    v.save(tmp_path / "v.npz")
    w = Volume.load(tmp_path / "v.npz")
    assert type(w.medium) is type(med) and w.boundary == "periodic-xy" and w.g == pytest.approx(0.3)
    np.testing.assert_array_equal(w.origin_mm, [1.0, -2.0, 0.5])
    assert w.quantization == q
    for key, arr in med.arrays().items():
        if key != "ink_names":
            np.testing.assert_array_equal(w.medium.arrays()[key], arr)


def test_with_mixture_keeps_geometry_and_inks():
    inside = np.ones((3, 4, 5), bool)
    inside[0, 0, 0] = False
    v = Volume(VOX, mixture=_mixture(), inks=INKS, inside=inside, origin_mm=(0, 0, 0))
    w = v.with_mixture(_mixture(seed=1))
    assert w.inks is INKS and w.inside is v.inside and w.origin_mm is not None
    np.testing.assert_array_equal(w.mixture, _mixture(seed=1))


@pytest.mark.parametrize("kw, needle", [
    (dict(), "exactly one of"),
    (dict(mixture=np.ones((2, 2, 2, 5), np.float32), labels=np.zeros((2, 2, 2), np.uint8), inks=INKS),
     "exactly one of"),
    (dict(mixture=np.ones((2, 2, 2, 4), np.float32), inks=INKS), "mixture must have shape"),
    (dict(mixture=np.ones((2, 2, 2, 5), np.float32)), "needs an ink table"),
    (dict(sigma_s=np.ones((2, 2, 2, 3), np.float32)), "needs both"),
    (dict(labels=np.full((2, 2, 2), 7, np.uint8), inks=INKS), "labels use ink 7"),
])
def test_bad_volumes_are_one_line_errors(kw, needle):
    with pytest.raises(VolumeError, match=needle) as e:
        Volume(VOX, **kw)
    assert "\n" not in str(e.value)


def test_require_mixture():
    lab = Volume(VOX, labels=np.zeros((2, 2, 2), np.uint8), inks=INKS)
    with pytest.raises(VolumeError, match="needs a mixture volume, got a labels volume"):
        lab.require_mixture("quantization")
