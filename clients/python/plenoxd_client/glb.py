"""What a binary glTF (.glb) mesh from plenoxd holds, read from its header and JSON chunk with
the standard library: vertex and triangle counts, and the asset's extras.plenoxd (the map's
source, the triangles before simplification, the simplification's error, the region the mesh
was cut to). The layout is core/formats/glb_mesh.h's; any GLB with triangle primitives reads.
"""

from __future__ import annotations

import json
import struct
from typing import Any, Dict, NamedTuple, Optional, Tuple

__all__ = ["GlbInfo", "read_glb_info"]

_MAGIC = 0x46546C67      # "glTF"
_JSON_CHUNK = 0x4E4F534A  # "JSON"

Box = Tuple[Tuple[float, float, float], Tuple[float, float, float]]


class GlbInfo(NamedTuple):
    """file_bytes: the header's total length; vertices, triangles: over every triangle
    primitive; full_triangles: before simplification (the extras', else triangles);
    lod_error_m: the simplification's error in metres; region: ((xmin, ymin, zmin), (xmax, ymax,
    zmax)) of a mesh cut to a box, else None; extras: the asset's extras.plenoxd as a dict."""
    file_bytes: int
    vertices: int
    triangles: int
    full_triangles: int
    lod_error_m: float
    region: Optional[Box]
    extras: Dict[str, Any]


def read_glb_info(data: bytes) -> GlbInfo:
    """The counts and extras of GLB `data` (at least its header and JSON chunk). ValueError
    naming the problem when it is not a glTF 2 binary file or its JSON chunk is cut."""
    if len(data) < 20:
        raise ValueError(f"not a GLB: {len(data)} bytes, the header needs 20")
    magic, version, length, chunk_length, chunk_type = struct.unpack_from("<5I", data, 0)
    if magic != _MAGIC or version != 2:
        raise ValueError("not a glTF 2 binary file (magic \"glTF\", version 2)")
    if chunk_type != _JSON_CHUNK:
        raise ValueError("GLB: the first chunk is not JSON")
    if len(data) < 20 + chunk_length:
        raise ValueError(f"GLB: the JSON chunk needs {20 + chunk_length} bytes, "
                         f"{len(data)} given")
    gltf = json.loads(data[20:20 + chunk_length].decode("utf-8"))
    accessors = gltf.get("accessors", [])
    vertices = triangles = 0
    for mesh in gltf.get("meshes", []):
        for primitive in mesh.get("primitives", []):
            if primitive.get("mode", 4) != 4:  # 4: triangles, the default
                continue
            count = accessors[primitive["attributes"]["POSITION"]]["count"]
            corners = accessors[primitive["indices"]]["count"] if "indices" in primitive \
                else count
            vertices += count
            triangles += corners // 3
    extras = gltf.get("asset", {}).get("extras", {}).get("plenoxd", {})
    region = None
    if isinstance(extras.get("region"), dict):
        lo, hi = extras["region"].get("min"), extras["region"].get("max")
        if isinstance(lo, list) and isinstance(hi, list) and len(lo) == len(hi) == 3:
            region = (tuple(float(v) for v in lo), tuple(float(v) for v in hi))
    return GlbInfo(file_bytes=length, vertices=vertices, triangles=triangles,
                   full_triangles=int(extras.get("full_triangles", triangles)),
                   lod_error_m=float(extras.get("lod_error_m", 0.0)), region=region,
                   extras=extras)
