"""Peak memory of rendering a 60 M-voxel printer-resolution label volume (42.3 x 84.7 x 27 um voxels, random
CMYKW labels), top face, 1 spp.   .venv/bin/python bench/bench_labels_memory.py"""

import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine, write  # noqa: E402

from inkopt.model import InkTable, Texels, Volume  # noqa: E402
from inkopt.render import Renderer  # noqa: E402

shape = (180, 470, 709)
labels = np.random.default_rng(0).integers(0, 5, shape, dtype=np.uint8)
vol = Volume.from_labels(voxel_mm=(25.4 / 600, 25.4 / 300, 0.027), labels=labels, inks=InkTable.parse("vero-cmykw"))
tex = Texels.for_volume(vol, ["top"])
t0 = time.perf_counter()
res = Renderer(vol).render(tex, 1, 0)
out = {
    "voxels": int(np.prod(shape)),
    "texels": len(tex),
    "seconds": time.perf_counter() - t0,
    "peak_rss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20,
    **machine(),
}
print(out)
print("wrote", write("labels_memory.json", out))
