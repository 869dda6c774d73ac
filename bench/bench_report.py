"""Size and writing time of the soft-proof page (``inkopt report``) of existing run directories.

    .venv/bin/python bench/bench_report.py RUN [RUN ...] [--name report_pages.json]

Each run is reported in this process (``proof.write_proof``, to RUN/report.html) and its page size, the seconds
it took, the results shown, the atlas size and the run's texel count and evaluation samples are recorded in
bench/results/NAME. The runs are made beforehand, e.g. by ``inkopt demo`` (demo-out/slab, demo-out/spot) or by
``inkopt optimize MESH --height-mm 40`` and ``inkopt evaluate``; the page's size depends on how noisy the
predictions are (JPEG textures), so the evaluation's spp is recorded with it.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))
sys.path.insert(0, str(Path(__file__).resolve().parent))


def main() -> None:
    from common import machine, write

    from inkopt.proof import write_proof

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+")
    ap.add_argument("--name", default="report_pages.json")
    args = ap.parse_args()
    rows = []
    for run in args.runs:
        p = write_proof(run)
        rep = json.loads((Path(run) / "report.json").read_text())
        ev_path = Path(run) / "evaluation.json"
        ev = json.loads(ev_path.read_text()) if ev_path.is_file() else {}
        rows.append(
            {
                "run": str(run),
                "kind": ev.get("kind", "slab" if "size_mm" in rep else "mesh"),
                "height_mm": rep.get("height_mm"),
                "size_mm": rep.get("size_mm"),
                "texels": rep.get("texels"),
                "evaluation_spp": ev.get("spp"),
                "page_mb": p.bytes / 1e6,
                "seconds": p.seconds,
                "results": p.results,
                "atlas": p.atlas,
                "downsampled": p.downsampled,
            }
        )
        print(json.dumps(rows[-1]))
    print(write(args.name, {"machine": machine(), "pages": rows}))


if __name__ == "__main__":
    main()
