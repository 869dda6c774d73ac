"""Type stub of ``inkopt._core``, the Rust core's bindings (``crates/py``): the ``Scene`` class (render and
gradients), its argument classes ``Medium`` (dense, sparse or label form) and ``Texels``, and the printing and
optimiser kernels.

Array conventions: grids are (z, y, x[, c]) C-contiguous arrays; texel voxels are (z, y, x); normals, directions
and voxel sizes are (x, y, z); lengths in mm, coefficients in mm^-1, radiance linear RGB. Bad input raises
ValueError. ``tests/test_core_stub.py`` checks this stub against the compiled module.
"""

import numpy as np
from numpy.typing import NDArray

__version__: str

class Medium:
    """A scene's medium as references to the caller's arrays, checked once; built by dense, sparse, band or labels."""

    @staticmethod
    def dense(sigma_s: NDArray[np.float32], sigma_a: NDArray[np.float32]) -> Medium:
        """Coefficients of every grid voxel: sigma_s, sigma_a (Z,Y,X,3) f32 C-contiguous, mm^-1."""

    @staticmethod
    def sparse(index: NDArray[np.int64], sigma_s: NDArray[np.float32], sigma_a: NDArray[np.float32]) -> Medium:
        """Voxels index (K,) i64 (strictly increasing linear zyx; the rest vacuum) with (K,3) f32 mm^-1 each."""

    @staticmethod
    def band(
        inside: NDArray[np.uint8],
        index: NDArray[np.int64],
        sigma_s: NDArray[np.float32],
        sigma_a: NDArray[np.float32],
        core_sigma_s: NDArray[np.float32],
        core_sigma_a: NDArray[np.float32],
    ) -> Medium:
        """Band voxels index (K,) i64 of inside (Z,Y,X) u8 with (K,3) f32, other inside voxels the core's (3,) f32."""

    @staticmethod
    def labels(
        labels: NDArray[np.uint8] | LabelBricks, ink_sigma_s: NDArray[np.float32], ink_sigma_a: NDArray[np.float32]
    ) -> Medium:
        """Labels (Z,Y,X) u8 (255: vacuum) or LabelBricks with every plane pushed, the ink table (N,3) f32 mm^-1 each."""

    @property
    def form(self) -> str:
        """ "dense", "sparse", "band" or "labels"."""

class LabelBricks:
    """A label grid built from its z-planes pushed in order and stored by 8^3 bricks, for Medium.labels."""

    def __new__(cls, shape: tuple[int, int, int]) -> LabelBricks:
        """An empty builder for a grid of shape (Z,Y,X)."""

    def push(self, planes: NDArray[np.uint8]) -> None:
        """The next z-planes, (K,Y,X) u8 C-contiguous; ValueError for another (Y,X) or more planes than are left."""

    @property
    def planes_left(self) -> int:
        """Planes not pushed yet (0 once the bricks are taken)."""

    @property
    def shape(self) -> tuple[int, int, int]:
        """The grid's shape (Z,Y,X)."""

class Texels:
    """Texels of a render or gradient pass, converted and checked once (28 bytes per texel)."""

    def __new__(cls, voxel: NDArray[np.int32], face: NDArray[np.uint8], normal: NDArray[np.float32]) -> Texels:
        """voxel (I,3) i32 zyx, face (I,) u8 (0..5), normal (I,3) f32 xyz outward (made unit)."""

    def __len__(self) -> int:
        """The number of texels."""

class Scene:
    """A voxel scene (geometry, medium, light, thread pool) that renders texel lists and accumulates gradients."""

    def __new__(
        cls,
        shape: tuple[int, int, int],
        voxel_mm: tuple[float, float, float],
        medium: Medium,
        *,
        inside: NDArray[np.uint8] | str | None = None,
        normals: NDArray[np.float32] | None = None,
        normal_index: NDArray[np.int64] | None = None,
        normal_vectors: NDArray[np.float32] | None = None,
        boundary: str = "box",
        ior: float = 1.5,
        g: float = 0.4,
        threads: int | None = None,
    ) -> Scene:
        """Grid shape (z,y,x) of voxel_mm (x,y,z) mm voxels and its medium; normals dense or sparse (index, vectors)."""

    def set_medium(self, medium: Medium) -> None:
        """Replace the medium (in place if of the same form and voxels), keeping geometry, pool and gradient buffers."""

    def set_voxels(self, index: NDArray[np.int64], sigma_s: NDArray[np.float32], sigma_a: NDArray[np.float32]) -> None:
        """Overwrite voxels index (K,) i64 (linear zyx) of a dense/sparse medium (or a band medium's band) with (K, 3) f32 mm^-1, in place."""

    def in_band(self, index: NDArray[np.int64]) -> NDArray[np.bool_]:
        """(K,) bool: whether each voxel of index (K,) i64 is in the band of a band medium."""

    def set_light(self, map: NDArray[np.float32] | None = None, rotate_deg: float = 0.0) -> None:
        """Light by an equirectangular map (H, 2H, 3) f32 linear radiance turned rotate_deg about z; None: uniform 1."""

    @property
    def threads(self) -> int:
        """Threads of the scene's pool."""

    @property
    def distance_storage(self) -> tuple[int, int, int] | None:
        """(bricks, stored_bricks, bytes) of the inside mask's signed distances stored by 8^3 bricks; None: no mask."""

    def render(
        self,
        texels: Texels,
        *,
        spp: int,
        seed: int,
        first_texel: int = 0,
        include_specular: bool = True,
        hero: bool = False,
    ) -> tuple[NDArray[np.float32], NDArray[np.float32], dict[str, int]]:
        """Render texels (first: index first_texel) -> mean, var_mean (I,3) f32, stats; hero: paths carry 3 channels."""

    def zero_grad(
        self, max_abs_adjoint: float, grad_index: NDArray[np.int32] | NDArray[np.int64] | None = None
    ) -> None:
        """Reset gradient buffers: per voxel, per slot of a (z,y,x) i32 slot map (-1: none) or of (F,) i64 voxels."""

    def backward(
        self,
        texels: Texels,
        adjoint: NDArray[np.float32],
        *,
        spp: int,
        seed: int,
        first_texel: int = 0,
        include_specular: bool = True,
        method: str = "replay",
        hero: bool = False,
    ) -> tuple[NDArray[np.float32], NDArray[np.float32], dict[str, int]]:
        """Accumulate adjoint (I,3) f32 . d colour / d sigma ("replay", "li1"; hero: replay); returns its own render."""

    def take_grad(self) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """d e/d sigma_s, d e/d sigma_a: (z,y,x,3) f32 each, or (F,3) per slot; frees the buffers block by block."""

    def take_grad_fixed(self) -> tuple[NDArray[np.int64], NDArray[np.int64], float]:
        """The gradients as raw fixed-point sums (int64, shaped as take_grad's) and the quantum; frees the buffers."""

def diffuse_layer(
    mixture: NDArray[np.float32],
    inside: NDArray[np.uint8],
    inside_next: NDArray[np.uint8],
    error: NDArray[np.float32],
    z: int,
    out: NDArray[np.uint8],
) -> None:
    """Error-diffuse layer z: mixture (N,Y,X) f32, masks (Y,X) u8, error (2,Y,X,N) f32 -> labels into out (Y,X) u8."""

def diffuse_counts_layer(
    share: NDArray[np.float64],
    block: NDArray[np.uint32],
    inside: NDArray[np.uint8],
    inside_next: NDArray[np.uint8],
    error: NDArray[np.float64],
    z: int,
    down: float,
    counts: NDArray[np.uint32],
    thresholds: NDArray[np.float64] | None = None,
) -> float:
    """Counts of layer z: share (N,y,x), block (y,x), classes (y,x) (255: the thresholds' own) -> counts; max |r|."""

def mark_smooth(
    share: NDArray[np.float64],
    classes: NDArray[np.uint8],
    smooth: float,
    below: NDArray[np.float64] | None = None,
    below_inside: NDArray[np.uint8] | None = None,
) -> None:
    """Sets 255 in classes (y,x) u8 where the RMS share distance of share (N,y,x) to the inside neighbours < smooth."""

def sort_blocks(
    t: NDArray[np.float32],
    ry: NDArray[np.uint32],
    rx: NDArray[np.uint32],
    order: NDArray[np.uint32],
    sorted: NDArray[np.float64],
) -> None:
    """Each block's printer voxels of t (k,Y,X) f32 by threshold -> order (ny,nx,W) u32 flat, sorted (ny,nx,W) f64."""

def place_blocks(
    order: NDArray[np.uint32],
    counts: NDArray[np.uint32],
    ry: NDArray[np.uint32],
    rx: NDArray[np.uint32],
    labels: NDArray[np.uint8],
) -> None:
    """Each block's voxels in order (ny,nx,W) take its counts (ny,nx,N) bands in turn -> labels (k,Y,X) u8 bands."""

def feature_plane(
    z: int, site_z: NDArray[np.int32], sampling: tuple[float, float, float], out: NDArray[np.int32]
) -> None:
    """Plane z of scipy's exact feature transform: site_z (Y,X) i32 (-1 none) -> nearest (z,y,x) in out (3,Y,X) i32."""

def smooth_rows(
    shape: tuple[int, int, int],
    index: NDArray[np.int64],
    values: NDArray[np.float32],
    steps: int,
    alpha: float,
    guide: NDArray[np.float32] | None = None,
    tau: float = 1.0,
    threads: int | None = None,
    rows: NDArray[np.uint32] | None = None,
    guide_key: NDArray[np.uint32] | None = None,
    guide_extra: NDArray[np.float32] | None = None,
) -> None:
    """Diffuse rows (K,) u32 of values (F, C) f32 in place; row r's guide: guide[guide_key[r]], guide_extra[r]."""

def softmax_rows(x: NDArray[np.float32], threads: int | None = None) -> NDArray[np.float32]:
    """The softmax of each row of x (rows, n) f32 -> (rows, n) f32."""

def softmax_backward(
    x: NDArray[np.float32],
    g: NDArray[np.float32],
    scale: NDArray[np.float32],
    natural: bool,
    threads: int | None = None,
) -> NDArray[np.float32]:
    """Softmax backward map: x, g = dE/dp (rows, n) f32, scale (rows,) f32 -> c (natural) or dE/dx, (rows, n) f32."""

def momentum_step(
    x: NDArray[np.float32],
    m: NDArray[np.float32],
    g: NDArray[np.float32],
    beta: float,
    lr: float,
    bias: float,
    scale: float,
    threads: int | None = None,
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """m' = beta m + (1 - beta) g, x' = x - (lr (m' / bias)) / scale in f32, arrays (rows, n) f32 -> (x', m')."""

def abs_order_statistics(values: NDArray[np.float32], ranks: list[int], threads: int | None = None) -> list[float]:
    """|values| (rows, n) f32 at the given 0-based ranks of their increasing order (exact; NaN if any is NaN)."""
