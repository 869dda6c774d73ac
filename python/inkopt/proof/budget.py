"""The soft-proof page's size budget: the page is written to stay within ``ProofOptions.max_mb`` whatever the
object's texels, results and lights.

The page's size is mostly its pictures (a mesh's JPEG texture atlases, a slab's PNG face pictures); the rest (the
vendored viewer, geometry, tables, loss curve) does not depend on them. The page is first composed as it always
is; only if it is over the budget are its pictures made smaller, and the page is composed again, until it fits:

- a mesh's atlas first loses pixels per texel at JPEG quality ``JPEG_QUALITY``, down to one pixel per texel
  (the cell size predicted from the bytes the pictures took, as bytes grow with the atlas's pixels), then its
  JPEG quality falls by ``QUALITY_STEP`` down to ``MIN_QUALITY``, then the atlas shrinks below one pixel per
  texel down to cells of ``bake.MIN_CELL`` pixels;
- a slab's face pictures show every ``step``-th texel along each side (the smallest step predicted to fit).

Every result and every light stays on the page; the page says when and how far its pictures were reduced. Each
composed page is measured, so the page written is within the budget; a budget that cannot hold the page even
with the smallest pictures is refused, naming ``max_mb``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from ..errors import ParameterError
from .bake import ATLAS_MAX, MARGIN, MIN_CELL, MeshAtlas

MB = 1_000_000  # bytes per MB of the budget (as ``inkopt report`` prints the page's size)
DEFAULT_MAX_MB = 30.0
JPEG_QUALITY = 90  # a mesh's textures and heat maps, where the budget allows
MIN_QUALITY = 60  # the lowest JPEG quality the budget goes to before the atlas drops below one pixel per texel
QUALITY_STEP = 5  # small enough that one step down does not leave much of the budget unused
SAFETY = 0.9  # the share of the predicted room a smaller choice aims at (bytes per pixel grow as pixels shrink)


@dataclass(frozen=True)
class ProofOptions:
    """Options of the soft-proof page (``write_proof``): ``max_mb`` the page's size budget in MB (10^6 bytes)."""

    max_mb: float = DEFAULT_MAX_MB

    def __post_init__(self):
        if not (isinstance(self.max_mb, (int, float)) and math.isfinite(self.max_mb) and self.max_mb > 0):
            raise ParameterError(f"`max_mb` must be a positive number of MB, got {self.max_mb!r}")

    @property
    def max_bytes(self) -> int:
        return int(self.max_mb * MB)


@dataclass(frozen=True)
class Composed:
    """One composed page: its bytes and how many of them are pictures (the part the budget can shrink)."""

    page: bytes
    picture_bytes: int


@dataclass(frozen=True)
class Fitted:
    """The page that fits: ``page`` bytes; ``atlas`` (meshes; None for slabs) and its JPEG ``quality`` (0 for
    slabs); ``step`` (slabs: one pixel per ``step`` x ``step`` texels; 1 for meshes); ``reduced``: whether the
    budget made the pictures smaller than the page's own choice; ``tries``: pages composed; ``first_bytes``: the
    size of the page as it chose its pictures itself (the first composed)."""

    page: bytes
    atlas: MeshAtlas | None
    quality: int
    step: int
    reduced: bool
    tries: int
    first_bytes: int


def _too_small(options: ProofOptions, what: str) -> ParameterError:
    return ParameterError(f"`max_mb` {options.max_mb:g} MB cannot hold the report page: {what}")


def _share(c: Composed, options: ProofOptions) -> float:
    """The share of the pictures' bytes that fits (``options`` minus the rest of the page, over the pictures);
    a page whose other parts alone are over the budget is refused."""
    rest = len(c.page) - c.picture_bytes
    if rest >= options.max_bytes or c.picture_bytes <= 0:
        raise _too_small(options, f"without its pictures it is {rest / MB:.2f} MB")
    return (options.max_bytes - rest) / c.picture_bytes


def one_pixel_cell(atlas: MeshAtlas) -> int:
    """The atlas cell size (pixels per side) at which an atlas pixel spans about one texel (``bake.mesh_atlas``:
    ``pixel_mm = edge / (cell - 1.5)``)."""
    edge_mm = atlas.pixel_mm * (atlas.cell - 2 * MARGIN)
    return max(MIN_CELL, math.ceil(edge_mm / atlas.texel_mm + 2 * MARGIN))


def _smaller_cell(cell: int, share: float, floor: int) -> int:
    """A cell below ``cell`` (not below ``floor``) whose atlas holds about ``share`` of the pixels, less
    ``SAFETY``."""
    return max(floor, min(cell - 1, int(cell * math.sqrt(max(share, 0.0) * SAFETY))))


def next_mesh_choice(cell: int, quality: int, share: float, one: int) -> tuple[int, int] | None:
    """The next smaller (cell, JPEG quality) after (``cell``, ``quality``) for pictures that must shrink to
    ``share`` of their bytes, ``one`` being the cell of one pixel per texel; None when nothing is smaller."""
    if quality >= JPEG_QUALITY and cell > one:
        return _smaller_cell(cell, share, one), quality
    if quality > MIN_QUALITY:
        return cell, max(MIN_QUALITY, quality - QUALITY_STEP)
    if cell > MIN_CELL:
        return _smaller_cell(cell, share, MIN_CELL), quality
    return None


def fit_mesh(
    build_atlas: Callable[[int], MeshAtlas],
    compose: Callable[[MeshAtlas, int, bool], Composed],
    options: ProofOptions,
) -> Fitted:
    """The mesh page within ``options.max_mb``: ``build_atlas(max_size)`` lays out the atlas (at most ``max_size``
    pixels a side), ``compose(atlas, quality, reduced)`` composes the page with its JPEG pictures at ``quality``
    (``reduced``: the budget made them smaller, which the page says). The first page is the page's own choice
    (``bake.ATLAS_MAX``, ``JPEG_QUALITY``); a page over the budget is composed again smaller
    (``next_mesh_choice``) until it fits. Raises ParameterError naming ``max_mb`` if even the smallest does not."""
    atlas, quality = build_atlas(ATLAS_MAX), JPEG_QUALITY
    c, tries = compose(atlas, quality, False), 1
    first, one = len(c.page), one_pixel_cell(atlas)
    while len(c.page) > options.max_bytes:
        nxt = next_mesh_choice(atlas.cell, quality, _share(c, options), one)
        if nxt is None:
            smallest = f"{atlas.size} x {atlas.size} pixels, JPEG quality {quality}"
            raise _too_small(options, f"with its smallest textures ({smallest}) it is {len(c.page) / MB:.2f} MB")
        cell, quality = nxt
        if cell != atlas.cell:
            atlas = build_atlas(atlas.grid * cell)
        c, tries = compose(atlas, quality, True), tries + 1
    return Fitted(c.page, atlas, quality, 1, tries > 1, tries, first)


def fit_slab(compose: Callable[[int], Composed], largest_side: int, options: ProofOptions) -> Fitted:
    """The slab page within ``options.max_mb``: ``compose(step)`` composes it with face pictures of every
    ``step``-th texel along each side; step 1 first, then the smallest step predicted to fit (pixels fall as
    step², ``largest_side`` the widest face's texels: the last step). Raises ParameterError naming ``max_mb`` if
    even one pixel per face does not fit."""
    step = 1
    c, tries = compose(step), 1
    first = len(c.page)
    while len(c.page) > options.max_bytes:
        share = _share(c, options)
        if step >= largest_side:
            raise _too_small(options, f"with one pixel per face it is {len(c.page) / MB:.2f} MB")
        step = min(largest_side, max(step + 1, math.ceil(step / math.sqrt(share * SAFETY))))
        c, tries = compose(step), tries + 1
    return Fitted(c.page, None, 0, step, step > 1, tries, first)
