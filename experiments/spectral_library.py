"""The spectral form of the ink library (the paper's RGB inks), fitted to reproduce the RGB table's colours, for
``<preset>@spectral`` (``model.spectral.load_ink_table``): writes python/inkopt/data/ink_spectra_20nm.json and
ink_spectra_10nm.json (spectral ink files) and experiments/results/spectral_library.json (how closely they, and
the linear upsampling ``SpectralInkTable.from_rgb``, reproduce the RGB table's colours under D65).

The fit (``calibration.spectral.spectral_form``), on the 20 nm grid: every patch of the calibration chart of
all ten library inks (``calibration.chart.design_chart``: each ink pure at nine thicknesses over white and alone,
diluted in white, every pair and triple of colour inks; 352 patches) predicted by the RGB table, its linear-RGB
reflectance upsampled to a spectrum with the Mallett-Yuksel sRGB basis, and the spectral table fitted to those
spectra band by band (g kept at 0.4), from the linear form. The 10 nm form is the 20 nm one interpolated
(``SpectralInkTable.resampled``). Reproduction is measured on the library chart and on the CMYKW chart: ΔE2000
under D65 between the RGB table's colour (linear RGB, Bradford D65 -> D65 is the identity) and the spectral
table's (band reflectance integrated under D65, ASTM E308).

    OPENBLAS_NUM_THREADS=1 nice -n 5 .venv/bin/python experiments/spectral_library.py [--iterations 30]
"""

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # adding-doubling's 16x16 solves: 40x faster on one thread

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import add_study_entry, machine  # noqa: E402

from inkopt.calibration.chart import design_chart  # noqa: E402
from inkopt.calibration.fit import predict_rgb  # noqa: E402
from inkopt.calibration.measure import rgb_to_lab, spectral_to_lab  # noqa: E402
from inkopt.calibration.spectral import predict_reflectance, spectral_form  # noqa: E402
from inkopt.color import delta_e2000  # noqa: E402
from inkopt.model import INK_LIBRARY, InkTable  # noqa: E402
from inkopt.model.spectral import (  # noqa: E402
    LIBRARY_SPECTRA,
    WAVELENGTHS_10NM,
    WAVELENGTHS_20NM,
    SpectralInkTable,
    write_spectral_ink_file,
)


def reproduction(chart, rgb: InkTable, spectral: SpectralInkTable) -> dict:
    """ΔE2000 under D65 between the RGB table's and the spectral table's colours of ``chart`` (inks in order)."""
    ref = rgb_to_lab(predict_rgb(chart, rgb), "D65")
    de = delta_e2000(spectral_to_lab(spectral.wavelengths_nm, predict_reflectance(chart, spectral), "D65"), ref)
    return {"mean": float(de.mean()), "p95": float(np.percentile(de, 95)), "max": float(de.max())}


def subset(table: SpectralInkTable, names) -> SpectralInkTable:
    rows = [table.index(n) for n in names]
    return SpectralInkTable(tuple(names), table.wavelengths_nm, table.sigma_s[rows], table.sigma_a[rows], table.g)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--iterations", type=int, default=30)
    a = ap.parse_args()
    library = InkTable.from_names(list(INK_LIBRARY))
    chart = design_chart(library.names)
    cmykw = InkTable.parse("vero-cmykw")
    cmykw_chart = design_chart(cmykw.names)
    command = "OPENBLAS_NUM_THREADS=1 nice -n 5 python experiments/spectral_library.py " + " ".join(sys.argv[1:])
    t0 = time.perf_counter()
    fit = spectral_form(library, WAVELENGTHS_20NM, chart, a.iterations)
    fit_entry = {"patches": len(chart), "evaluations": fit.iterations, "converged": fit.converged}
    fit_entry["seconds"] = time.perf_counter() - t0
    for step, table in ((20, fit.inks), (10, fit.inks.resampled(WAVELENGTHS_10NM))):
        linear = SpectralInkTable.from_rgb(library, table.wavelengths_nm)
        entry = {
            "bands": table.bands,
            "made": "fitted" if step == 20 else "the 20 nm fit interpolated",
            "fit": fit_entry,
            "library_chart_fitted": reproduction(chart, library, table),
            "library_chart_linear": reproduction(chart, library, linear),
            "cmykw_chart_fitted": reproduction(cmykw_chart, cmykw, subset(table, cmykw.names)),
            "cmykw_chart_linear": reproduction(cmykw_chart, cmykw, subset(linear, cmykw.names)),
        }
        print(f"{step} nm: {entry}", flush=True)
        prov = {"made_by": command, "method": "calibration.spectral.spectral_form on the library chart", **entry}
        write_spectral_ink_file(LIBRARY_SPECTRA[float(step)], table, prov)
        entry.update(command=command, machine=machine())
        print(f"wrote {add_study_entry('spectral_library.json', f'{step}nm', entry)}")


if __name__ == "__main__":
    main()
