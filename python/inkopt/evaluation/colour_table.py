"""The colour -> mixture table of an ink set: what a print shop measures, used by the baselines (docs/method.md §8).

- The table (``colour_table``) holds the rendered colour of infinite homogeneous patches (``boundary =
  "periodic-xy"``, one layer of ``patch_mm`` = 2.5 mm by default, i.e. a print shop's fixed-thickness colour
  chart rather than a per-object one) for the mixtures of ``table_mixtures``: a simplex lattice of the ink set
  (step 1/8 for up to 5 inks, see ``default_step``) plus its "tint" warp u*u/|u|^2, which adds small shares
  (1/50, 1/38, ...) where colour changes fastest with the mixture (the first 1/8 of black or of a colourant in
  white moves ΔE by 10-30); 970 mixtures for CMYKW. The warp makes a random mixture's colour come back from the
  look-up several times closer than the plain 1/8 lattice does, and closer than a finer uniform lattice with
  more patches (a one-off check, its figures in docs/experiments.md, "Evaluation time and memory"). Each patch is
  seen from its top face under the renderer's uniform white environment (specular reflection included, as in
  evaluation), rendered adaptively until the standard error of its CIELAB colour is below ``max_stderr`` (0.3
  ΔE76 by default). The table is cached on disk (``$INKOPT_CACHE_DIR``, else
  ``$XDG_CACHE_HOME/inkopt``, else ``~/.cache/inkopt``), keyed by a hash of the ink table, g, ior, patch
  thickness, lattice step, error target and the inkopt version; written atomically. The default ink set's table
  ships with the package (``PACKAGED``), so only another set's is built (once; then cached).
- ``ColourTable.lookup`` maps a target colour to a mixture: by default (``refine=True``) a convex blend of the
  k = 8 entries nearest in CIELAB, with the weights minimising the ΔE76 between the target and the blend of the
  entries' colours (simplex-constrained least squares, i.e. assuming colour is locally linear in the mixture);
  ``refine=False`` takes the mixture of the single nearest entry (less accurate: the lattice's spacing adds to the
  error).

Conventions (docs/conventions.md): mixtures (M, N); colours linear RGB; CIELAB via ``inkopt.color``.
"""

from __future__ import annotations

import hashlib
import itertools
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from ..color import lab_stderr, linear_to_lab
from ..errors import ParameterError
from ..io import save_npz
from ..model import InkTable, Texels, Volume
from ..render import Renderer

DEFAULT_PATCH_MM = 2.5
DEFAULT_MAX_STDERR = 0.3  # ΔE76 standard error of each table colour
MAX_TABLE_ENTRIES = 600  # default_step picks the finest step with at most this many mixtures
PATCH_LATERAL = 8  # texels per side of a patch (periodic; 64 texels keep all threads busy)
PATCH_LATERAL_MM = 0.25  # lateral voxel size of a patch (irrelevant for a homogeneous periodic medium)
PATCH_PILOT_SPP = 16  # spp of the pilot render of every patch
MAX_PATCH_SPP = 8192
REFINE_K = 8
TABLE_VERSION = 2


# ----------------------------------------------------------------------------------------------- lattice
def simplex_lattice(n_inks: int, step: int) -> np.ndarray:
    """All mixtures with weights in {0, 1/step, ..., 1} summing to 1: (C(step + N - 1, N - 1), N) float32,
    in lexicographic order of the bar positions (stars and bars)."""
    if n_inks < 1 or step < 1:
        raise ValueError(f"lattice needs n_inks >= 1 and step >= 1, got {n_inks}, {step}")
    combos = list(itertools.combinations(range(step + n_inks - 1), n_inks - 1))
    bars = np.array(combos, np.int64).reshape(len(combos), n_inks - 1)
    edges = np.concatenate([np.full((len(bars), 1), -1), bars, np.full((len(bars), 1), step + n_inks - 1)], 1)
    return (np.diff(edges, axis=1) - 1).astype(np.float32) / step


def default_step(n_inks: int, max_entries: int = MAX_TABLE_ENTRIES) -> int:
    """The finest lattice step among 8, 6, 4, 3, 2 whose uniform lattice has at most ``max_entries`` mixtures
    (8 -> 495 for 5 inks; 6 -> 462 for 6 inks; 4 -> 330 for 8 inks); ``table_mixtures`` about doubles them."""
    from math import comb

    for step in (8, 6, 4, 3, 2):
        if comb(step + n_inks - 1, n_inks - 1) <= max_entries:
            return step
    return 1


def table_mixtures(n_inks: int, step: int) -> np.ndarray:
    """The table's mixtures: ``simplex_lattice(n_inks, step)`` and its tint warp u*u/|u|^2 (row-normalised),
    without duplicates, rows in ascending lexicographic order. (M, N) float32."""
    u = simplex_lattice(n_inks, step).astype(np.float64)
    w = u * u
    w /= w.sum(1, keepdims=True)
    both = np.round(np.concatenate([u, w]), 7)
    return np.unique(both, axis=0).astype(np.float32)


# ----------------------------------------------------------------------------------------------- table
def cache_dir() -> Path:
    if os.environ.get("INKOPT_CACHE_DIR"):
        return Path(os.environ["INKOPT_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "inkopt"


#: tables shipped with the package (the default ink set's), read like the cache: a first run need not build them
PACKAGED = Path(__file__).resolve().parents[1] / "data" / "colour_tables"


def _read_table(path: Path, inks: InkTable, key: str) -> ColourTable | None:
    """The table stored at ``path`` if it is readable and made for ``inks`` with ``key``, else None (an unreadable
    cache entry is rebuilt and overwritten)."""
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as d:
            if tuple(str(n) for n in d["ink_names"]) == tuple(inks.names) and str(d["key"]) == key:
                return ColourTable(
                    tuple(inks.names),
                    d["mixtures"],
                    d["rgb"],
                    d["lab"],
                    d["stderr"],
                    float(d["patch_mm"]),
                    int(d["step"]),
                    key,
                    float(d["seconds"]),
                    cached=True,
                )
    except (OSError, ValueError, KeyError):
        pass
    return None


def table_key(inks: InkTable, g: float, ior: float, patch_mm: float, step: int, max_stderr: float) -> str:
    """Hex digest identifying a table (changes with anything that changes its colours)."""
    from .. import __version__

    h = hashlib.sha256()
    h.update(
        repr(
            (
                TABLE_VERSION,
                __version__,
                tuple(inks.names),
                round(float(g), 9),
                round(float(ior), 9),
                round(float(patch_mm), 9),
                int(step),
                round(float(max_stderr), 9),
            )
        ).encode()
    )
    # float32, as volume files store the ink table: a table built from InkTable.parse(...) is found again from a
    # volume loaded from disk
    h.update(np.ascontiguousarray(inks.sigma_s, np.float32).tobytes())
    h.update(np.ascontiguousarray(inks.sigma_a, np.float32).tobytes())
    return h.hexdigest()[:20]


@dataclass
class ColourTable:
    """Rendered colours of homogeneous patches.

    mixtures (M, N) float32; rgb (M, 3) float64 linear RGB of the patch's top face; lab (M, 3) float64;
    stderr (M,) float64 ΔE76 standard error of each lab; patch_mm, step; seconds = build time (when loaded from
    the cache: of the build that wrote it; ``cached`` tells).
    """

    ink_names: tuple
    mixtures: np.ndarray
    rgb: np.ndarray
    lab: np.ndarray
    stderr: np.ndarray
    patch_mm: float
    step: int
    key: str
    seconds: float = 0.0
    cached: bool = False

    def __post_init__(self):
        self._tree = cKDTree(self.points())

    def points(self) -> np.ndarray:
        """(M, D) the entries' colours the look-up searches and blends in: ``lab`` (a spectral table under several
        lights: their CIELAB side by side, ``spectral_table.SpectralColourTable``)."""
        return self.lab

    def target_points(self, lab_t: np.ndarray) -> np.ndarray:
        """(U, D) targets' CIELAB (U, 3) in the space of :meth:`points`."""
        return lab_t

    def lookup(self, target_rgb, refine: bool = True, k: int = REFINE_K, iterations: int = 300) -> np.ndarray:
        """Mixtures (I, N) float32 for target colours (I, 3) linear RGB (see module docstring)."""
        target = np.asarray(target_rgb, np.float64)
        if target.ndim != 2 or target.shape[1] != 3 or not np.all(np.isfinite(target)):
            raise ValueError(f"target colours must be finite (I, 3) linear RGB, got {target.shape}")
        uniq, inv = np.unique(target, axis=0, return_inverse=True)
        lab_t = self.target_points(linear_to_lab(uniq))
        k = int(min(k, len(self.lab)))
        if not refine or k < 2:
            _, idx = self._tree.query(lab_t, 1)
            return self.mixtures[idx][inv.reshape(-1)]
        _, idx = self._tree.query(lab_t, k)  # (U, k), nearest first
        w = simplex_least_squares(self.points()[idx] - lab_t[:, None, :], iterations)
        out = np.einsum("uk,ukn->un", w, self.mixtures[idx].astype(np.float64))
        return out.astype(np.float32)[inv.reshape(-1)]

    def reachable_lab(self, target_rgb, k: int = REFINE_K, iterations: int = 300) -> np.ndarray:
        """CIELAB (I, 3) of the colour nearest each target (I, 3 linear) that a thick homogeneous patch reaches:
        the refined look-up's predicted colour, the convex blend of the k nearest entries' colours closest to
        the target (an in-gamut target is reached exactly; the distance of an out-of-gamut one is to the local
        hull of the table, not to the lattice points, whose spacing would add to it)."""
        lab_t = linear_to_lab(np.asarray(target_rgb, np.float64))
        uniq, inv = np.unique(lab_t, axis=0, return_inverse=True)
        k = int(min(k, len(self.lab)))
        _, idx = self._tree.query(uniq, k)
        idx = idx.reshape(len(uniq), k)
        w = simplex_least_squares(self.lab[idx] - uniq[:, None, :], iterations)
        return np.einsum("uk,ukc->uc", w, self.lab[idx])[inv.reshape(-1)]

    def to_arrays(self) -> dict:
        return {
            "ink_names": np.array(self.ink_names),
            "mixtures": self.mixtures,
            "rgb": self.rgb,
            "lab": self.lab,
            "stderr": self.stderr,
            "patch_mm": np.float64(self.patch_mm),
            "step": np.int64(self.step),
            "key": np.array(self.key),
            "seconds": np.float64(self.seconds),
        }


def simplex_least_squares(b: np.ndarray, iterations: int = 300) -> np.ndarray:
    """Batched min_w |sum_j w_j b_j|^2 over the probability simplex, b (U, k, 3) -> w (U, k) float64.

    Accelerated projected gradient (FISTA) with step 1/L, L = the largest eigenvalue of B B^T; starts at the
    first entry (w = e_0) so the result is never worse than it.
    """
    b = np.asarray(b, np.float64)
    u, k, _ = b.shape
    lip = np.linalg.eigvalsh(np.einsum("ukc,ukd->ucd", b, b))[:, -1]
    step = 1.0 / np.maximum(lip, 1e-12)
    w = np.zeros((u, k))
    w[:, 0] = 1.0
    y, t = w.copy(), 1.0
    for _ in range(iterations):
        grad = np.einsum("ukc,uc->uk", b, np.einsum("uk,ukc->uc", y, b))
        w_new = _project_simplex(y - step[:, None] * grad)
        t_new = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * t * t))
        y = w_new + ((t - 1.0) / t_new) * (w_new - w)
        w, t = w_new, t_new
    return w


def _project_simplex(v: np.ndarray) -> np.ndarray:
    """Euclidean projection of each row of v (U, k) onto the probability simplex (sort-based)."""
    s = -np.sort(-v, axis=1)
    css = np.cumsum(s, axis=1) - 1.0
    ind = np.arange(1, v.shape[1] + 1)
    rho = np.sum(s - css / ind > 0, axis=1)
    theta = css[np.arange(len(v)), rho - 1] / rho
    return np.maximum(v - theta[:, None], 0.0)


def render_patches(
    mixtures,
    inks: InkTable,
    g: float,
    ior: float,
    patch_mm: float = DEFAULT_PATCH_MM,
    max_stderr: float = DEFAULT_MAX_STDERR,
    seed: int = 0,
    threads=None,
    progress: bool = False,
):
    """Render infinite homogeneous patches of ``mixtures`` (M, N): returns (rgb (M, 3), stderr (M,)).

    Each patch: a pilot of ``PATCH_PILOT_SPP`` spp on 64 texels, then (if its ΔE standard error exceeds
    ``max_stderr``) a second pass sized by the pilot's error (x1.2 margin, at most ``MAX_PATCH_SPP``);
    the two passes (independent seeds) are pooled per texel.
    """
    mixtures = np.asarray(mixtures, np.float32)
    texels = None
    rgb = np.zeros((len(mixtures), 3))
    err = np.zeros(len(mixtures))
    bar = None
    if progress and sys.stderr.isatty():
        from tqdm import tqdm

        bar = tqdm(total=len(mixtures), desc="colour table", unit="patch", leave=False)
    for j, row in enumerate(mixtures):  # a loop over table entries (hundreds), not voxels
        vol = Volume.from_mixture(
            voxel_mm=[PATCH_LATERAL_MM, PATCH_LATERAL_MM, patch_mm],
            inks=inks,
            g=g,
            ior=ior,
            mixture=np.broadcast_to(row, (1, PATCH_LATERAL, PATCH_LATERAL, len(row))).copy(),
            boundary="periodic-xy",
        )
        if texels is None:
            texels = Texels.for_volume(vol, ["top"])
        rgb[j], err[j] = _patch_colour(Renderer(vol, threads), texels, 2 * j + seed * 1_000_003, max_stderr)
        if bar is not None:
            bar.update()
    if bar is not None:
        bar.close()
    return rgb, err


def _patch_colour(rnd: Renderer, texels: Texels, seed: int, max_stderr: float) -> tuple[np.ndarray, float]:
    """One patch's mean colour (3,) linear RGB and its ΔE standard error: the pilot with ``seed``, and a second
    pass with ``seed + 1`` when the pilot's error exceeds ``max_stderr`` (``render_patches``)."""
    r0 = rnd.render(texels, PATCH_PILOT_SPP, seed=seed)
    m, v = r0.rgb.astype(np.float64), r0.var_mean.astype(np.float64)
    mean = m.mean(0)
    se = lab_stderr(mean, v.sum(0) / len(texels) ** 2)
    if se > max_stderr:
        spp1 = int(min(MAX_PATCH_SPP, np.ceil(PATCH_PILOT_SPP * ((se / max_stderr) ** 2 * 1.2 - 1.0))))
        r1 = rnd.render(texels, max(spp1, 1), seed=seed + 1)
        n0, n1 = PATCH_PILOT_SPP, r1.spp
        m = (n0 * m + n1 * r1.rgb) / (n0 + n1)
        v = (n0 * n0 * v + n1 * n1 * r1.var_mean) / (n0 + n1) ** 2
        mean = m.mean(0)
        se = lab_stderr(mean, v.sum(0) / len(texels) ** 2)
    return mean, se


def check_patch_settings(patch_mm: float, max_stderr: float) -> None:
    """The one check of a colour table's patch thickness (mm) and error target (ΔE76), RGB or spectral."""
    if not (np.isfinite(patch_mm) and patch_mm > 0):
        raise ParameterError(f"`patch_mm` must be a positive thickness in mm, got {patch_mm}")
    if not max_stderr > 0:
        raise ParameterError(f"`max_stderr` must be positive, got {max_stderr}")


def colour_table(
    inks: InkTable,
    g: float | None = None,
    ior: float = 1.5,
    patch_mm: float = DEFAULT_PATCH_MM,
    step: int | None = None,
    max_stderr: float = DEFAULT_MAX_STDERR,
    cache: bool = True,
    threads=None,
    progress: bool = False,
) -> ColourTable:
    """The colour -> mixture table of an ink set (module docstring); loaded from the cache when present.

    g defaults to the ink table's g. Built once per key, then read from the cache (or the package's copy).
    """
    g = inks.g if g is None else float(g)
    step = default_step(len(inks)) if step is None else int(step)
    check_patch_settings(patch_mm, max_stderr)
    key = table_key(inks, g, ior, patch_mm, step, max_stderr)
    path = cache_dir() / f"colour_table_{key}.npz"
    for where in (path, PACKAGED / path.name) if cache else ():
        table = _read_table(where, inks, key)
        if table is not None:
            return table
    t0 = time.perf_counter()
    mixtures = table_mixtures(len(inks), step)
    rgb, err = render_patches(mixtures, inks, g, ior, patch_mm, max_stderr, threads=threads, progress=progress)
    table = ColourTable(
        tuple(inks.names), mixtures, rgb, linear_to_lab(rgb), err, float(patch_mm), step, key, time.perf_counter() - t0
    )
    if cache:
        try:
            save_npz(path, table.to_arrays())
        except OSError as exc:
            print(f"inkopt: note: cannot cache the colour table in {path.parent} ({exc})", file=sys.stderr)
    return table
