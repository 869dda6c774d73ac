"""The figure of docs/spectral.md: one mixture's reflectance per band and its colour under each named light.

The mixture (40 % cyan, 25 % yellow, 35 % white, 2 mm over 2 mm of white) of the benchmark's spectral table
(bench/bench_spectral.py ``spectral_from_rgb``, 31 bands over 400-700 nm: an assumption, not a calibration), its
reflectance per band by adding-doubling (``calibration.stack.channel_reflectance``, the patch model the renderer is
tested against), the lights' relative power, and a swatch per light: the colour under that light relative to the
light's white (``spectral.lights``), shown as an adapted viewer sees it (its CIELAB drawn in sRGB).

    .venv/bin/python experiments/spectral_plot.py

Writes docs/spectral_mixture.png and experiments/results/spectral_mixture.json.
"""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from bench_spectral import spectral_from_rgb  # noqa: E402
from common import ROOT  # noqa: E402
from common import write_study as write  # noqa: E402

from inkopt.calibration.stack import channel_reflectance  # noqa: E402
from inkopt.color import RGB_TO_XYZ, WHITE_XYZ, to_srgb8  # noqa: E402
from inkopt.model import InkTable  # noqa: E402
from inkopt.spectral.lights import GRID_NM, NAMED, named_light  # noqa: E402

SHARE = np.array([0.40, 0.0, 0.25, 0.0, 0.35])  # cyan, magenta, yellow, black, white


def lab_to_srgb8(lab: np.ndarray) -> np.ndarray:
    """CIELAB (3,) relative to linear sRGB's white -> uint8 sRGB (clipped)."""
    fy = (lab[0] + 16.0) / 116.0
    f = np.array([fy + lab[1] / 500.0, fy, fy - lab[2] / 200.0])
    t = np.where(f > 6 / 29, f**3, 3 * (6 / 29) ** 2 * (f - 4 / 29))
    return to_srgb8(np.linalg.solve(RGB_TO_XYZ, t * WHITE_XYZ))


def main():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    inks = InkTable.parse("vero-cmykw")
    table = spectral_from_rgb(inks, 31)
    s, a = SHARE @ table.sigma_s, SHARE @ table.sigma_a
    white = inks.index("white")
    refl = np.array(
        [
            channel_reflectance([(s[b], a[b], 2.0), (table.sigma_s[white, b], table.sigma_a[white, b], 2.0)], table.g)
            for b in range(table.bands)
        ]
    )
    fig, (ax, sw) = plt.subplots(1, 2, figsize=(9, 3.4), gridspec_kw={"width_ratios": [2.2, 1]})
    ax.plot(table.wavelengths_nm, refl, "k.-", label="reflectance (adding-doubling per band)")
    ax.set_xlabel("wavelength (nm)")
    ax.set_ylabel("reflectance")
    ax.set_ylim(0, max(0.6, refl.max() * 1.1))
    ax2 = ax.twinx()
    labs = {}
    for name in NAMED:
        light = named_light(name)
        p = light.on_grid()
        ax2.plot(GRID_NM, p / p[(GRID_NM >= 400) & (GRID_NM <= 700)].max(), lw=0.8, label=name)
        labs[name] = light.colour_map(table.wavelengths_nm).lab(refl)
    ax2.set_ylabel("relative power (max over 400-700 nm = 1)")
    ax2.set_xlim(380, 720)
    ax2.set_ylim(0, 1.6)
    ax2.legend(loc="upper right", fontsize=7, ncol=3)
    ax.legend(loc="upper left", fontsize=7)
    for k, (name, lab) in enumerate(labs.items()):
        sw.add_patch(plt.Rectangle((0, -k), 0.35, 0.8, color=lab_to_srgb8(lab) / 255.0))
        sw.text(0.42, -k + 0.4, f"{name}: L*a*b* {lab[0]:.1f}, {lab[1]:.1f}, {lab[2]:.1f}", va="center", fontsize=8)
    sw.set_xlim(0, 1.6)
    sw.set_ylim(-len(labs) + 0.9, 0.9)
    sw.axis("off")
    sw.set_title("its colour under each light (adapted)", fontsize=9)
    fig.tight_layout()
    png = ROOT / "docs" / "spectral_mixture.png"
    fig.savefig(png, dpi=110)
    out = {
        "mixture": dict(zip(inks.names, SHARE.tolist())),
        "wavelengths_nm": table.wavelengths_nm.tolist(),
        "reflectance": refl.tolist(),
        "lab_under": {k: v.tolist() for k, v in labs.items()},
    }
    print("wrote", png, write("spectral_mixture.json", out))
    for k, v in labs.items():
        print(f"{k:7s} L*a*b* {v[0]:6.2f} {v[1]:6.2f} {v[2]:6.2f}")


if __name__ == "__main__":
    main()
