"""The volume model: explicit medium forms, typed optional fields, the .npz round trip, one-line errors."""

import numpy as np
import pytest

from inkopt.model import Dense, InkTable, Labels, Mixture, Quantization, Volume, VolumeError

INKS = InkTable.parse("vero-cmykw")
VOX = (0.0847, 0.0847, 0.0847)


def _mixture(shape=(3, 4, 5), seed=0):
    return np.random.default_rng(seed).dirichlet(np.ones(len(INKS)), size=shape).astype(np.float32)


def test_classmethod_and_medium_construction_agree():
    m = _mixture()
    a = Volume.from_mixture(VOX, mixture=m, inks=INKS)
    b = Volume(VOX, medium=Mixture(m, INKS))
    assert isinstance(a.medium, Mixture) and a.form == b.form == "mixture" and a.shape == (3, 4, 5)
    np.testing.assert_array_equal(a.mixture, b.mixture)
    assert a.inks is INKS and a.labels is None and a.sigma_s is None


@pytest.mark.parametrize("form", ["dense", "mixture", "labels"])
def test_file_round_trip_keeps_form_and_typed_fields(tmp_path, form):
    m = _mixture()
    if form == "dense":
        med = Dense(*Volume.from_mixture(VOX, mixture=m, inks=INKS).coefficients())
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
    v = Volume.from_mixture(VOX, mixture=_mixture(), inks=INKS, inside=inside, origin_mm=(0, 0, 0))
    w = v.with_mixture(_mixture(seed=1))
    assert w.inks is INKS and w.inside is v.inside and w.origin_mm is not None
    np.testing.assert_array_equal(w.mixture, _mixture(seed=1))


@pytest.mark.parametrize(
    "make, needle",
    [
        (lambda: Volume.from_mixture(VOX, np.ones((2, 2, 2, 4), np.float32), INKS), "mixture must have shape"),
        (lambda: Volume.from_labels(VOX, np.full((2, 2, 2), 7, np.uint8), INKS), "labels use ink 7"),
        (
            lambda: Volume.from_coefficients(
                VOX, np.ones((2, 2, 2, 3), np.float32), -np.ones((2, 2, 2, 3), np.float32)
            ),
            "negative",
        ),
        (lambda: Volume(VOX, np.ones((2, 2, 2, 3), np.float32)), "Dense, Mixture or Labels"),
        (lambda: Volume.from_mixture((0.1, 0.1), np.ones((2, 2, 2, 5), np.float32), INKS), "voxel_mm"),
    ],
)
def test_bad_volumes_are_one_line_errors(make, needle):
    with pytest.raises(VolumeError, match=needle) as e:
        make()
    assert "\n" not in str(e.value)


@pytest.mark.parametrize(
    "arrays, needle",
    [
        (dict(), "exactly one of"),
        (dict(mixture=np.ones((2, 2, 2, 5), np.float32), labels=np.zeros((2, 2, 2), np.uint8)), "exactly one of"),
        (dict(mixture=np.ones((2, 2, 2, 5), np.float32), ink_names=None), "needs an ink table"),
        (dict(sigma_s=np.ones((2, 2, 2, 3), np.float32)), "needs both"),
    ],
)
def test_bad_volume_files_are_one_line_errors(tmp_path, arrays, needle):
    full = {"voxel_mm": np.asarray(VOX), **INKS.to_arrays(), **arrays}
    np.savez(tmp_path / "v.npz", **{k: v for k, v in full.items() if v is not None})
    with pytest.raises(VolumeError, match=needle) as e:
        Volume.load(tmp_path / "v.npz")
    assert "\n" not in str(e.value)


def test_require_mixture():
    lab = Volume.from_labels(VOX, labels=np.zeros((2, 2, 2), np.uint8), inks=INKS)
    with pytest.raises(VolumeError, match="needs a mixture volume, got a labels volume"):
        lab.require_mixture("quantization")


@pytest.mark.parametrize("compressed_base", ["labels", "mixture"])
def test_mixture_written_in_slabs_reads_back_as_the_whole(tmp_path, compressed_base):
    """``save_with_mixture`` (the result of a big run, a slab of layers at a time) gives the file that
    ``with_mixture(whole).save`` gives, array by array; a bad slab or a short stream leaves no file behind."""
    from inkopt.model import SurfaceNormals

    m = _mixture((5, 4, 3), seed=2)
    inside = np.ones((5, 4, 3), bool)
    inside[0, 0, :2] = False
    med = Labels(np.zeros((5, 4, 3), np.uint8), INKS) if compressed_base == "labels" else Mixture(m * 0.5, INKS)
    normals = SurfaceNormals((5, 4, 3), np.array([1, 7, 30]), np.eye(3, dtype=np.float32))
    base = Volume(VOX, medium=med, inside=inside, normals=normals, origin_mm=(1.0, 2.0, 3.0))
    base.with_mixture(m).save(tmp_path / "whole.npz")
    base.save_with_mixture(tmp_path / "slabs.npz", (m[z : z + 2] for z in range(0, 5, 2)), INKS)
    with np.load(tmp_path / "whole.npz") as a, np.load(tmp_path / "slabs.npz") as b:
        assert sorted(a.files) == sorted(b.files) and "labels" not in b.files
        for k in a.files:
            np.testing.assert_array_equal(a[k], b[k])
    v = Volume.load(tmp_path / "slabs.npz")
    assert v.form == "mixture" and v.normals is not None
    bad = m.copy()
    bad[3, 1, 1, 0] = np.nan
    with pytest.raises(VolumeError, match="finite"):
        base.save_with_mixture(tmp_path / "bad.npz", (bad[z : z + 1] for z in range(5)), INKS)
    with pytest.raises(ValueError, match="rows"):
        base.save_with_mixture(tmp_path / "short.npz", iter([m[:2]]), INKS)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["slabs.npz", "whole.npz"]
