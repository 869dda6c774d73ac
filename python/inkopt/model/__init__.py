"""The data model shared by every stage: inks and ink sets (``inks``), the voxel volume in its three medium forms
(``volume``, its surface's shading normals in ``normals``, fixed ink shares in ``fixed``, the constraints
they express in ``constraints``), a mesh's provenance (``provenance``) and the renderer's sensor elements, texels
(``texels``); a mixture volume file read lazily, a layer or a block of voxels at a time (``mixturefile``)."""

from .constraints import TRANSPARENT_INKS, Translucency, scene_fixed_shares, transparent_ink, white_fixed_shares
from .fixed import FixedShares
from .inks import DEFAULT_G, INK_LIBRARY, PRESETS, InkTable, mix, mix_grad
from .media import Band
from .normals import SurfaceNormals
from .provenance import MeshInfo
from .texels import FACE_ALIASES, FACE_NAMES, FACE_NORMALS, Texels, face_id
from .volume import BOUNDARIES, EMPTY, MAX_VOLUME_BYTES, Dense, Labels, Mixture, Quantization, Volume, VolumeError

__all__ = [
    "DEFAULT_G",
    "INK_LIBRARY",
    "PRESETS",
    "InkTable",
    "mix",
    "mix_grad",
    "FACE_ALIASES",
    "FACE_NAMES",
    "FACE_NORMALS",
    "Texels",
    "face_id",
    "BOUNDARIES",
    "EMPTY",
    "MAX_VOLUME_BYTES",
    "Band",
    "Dense",
    "Labels",
    "Mixture",
    "Quantization",
    "Volume",
    "VolumeError",
    "SurfaceNormals",
    "FixedShares",
    "TRANSPARENT_INKS",
    "Translucency",
    "scene_fixed_shares",
    "transparent_ink",
    "white_fixed_shares",
    "MeshInfo",
]
