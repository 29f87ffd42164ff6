"""What datasets and capture sets record of an object: its SDFormat with the textures beside it,
and one record per front (part) in canonical order.

The generator's SDFormat names each texture by an absolute file:// URI in the texture cache
(`nfr_drake.objects.textures`), which another machine lacks. A folder that ships `object.sdf`
holds copies of its textures under `textures/`, and the SDFormat names them by relative path,
which Drake's parser resolves from the file's folder.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from urllib.parse import urlparse
from urllib.request import url2pathname

from nfr_drake.objects import ArticulatedObject, Part, to_sdformat

TEXTURES_DIR = "textures"


def texture_path(uri: str) -> Path:
    """The file of a texture named by a file:// URI or a plain path."""
    parsed = urlparse(uri)
    return Path(url2pathname(parsed.path)) if parsed.scheme == "file" else Path(uri)


def portable_sdformat(obj: ArticulatedObject) -> tuple[str, dict[str, Path]]:
    """SDFormat of `obj` naming its textures `textures/<file name>`, and relative path -> the
    texture file to copy there (empty for an object without textures)."""
    sources: dict[str, Path] = {}

    def relocate(part: Part) -> Part:
        if part.texture is None:
            return part
        source = texture_path(part.texture)
        rel = f"{TEXTURES_DIR}/{source.name}"
        sources[rel] = source
        return replace(part, texture=rel)

    moved = replace(obj, base_parts=tuple(map(relocate, obj.base_parts)),
                    fronts=tuple(replace(f, parts=tuple(map(relocate, f.parts))) for f in obj.fronts))
    return to_sdformat(moved), sources


PART_ORDER = ("canonical: by the left edge of the front (increasing y in O, to the mm), then by its "
              "top edge (decreasing z): columns left to right as seen from the front, top to bottom "
              "within a column (docs/FURNITURE.md)")
"""The order of `parts` in meta.json and gt.json, stated in both."""


def front_record(obj: ArticulatedObject, k: int) -> dict:
    """What stays fixed of front k (JSON-ready, O frame, m and rad): type, link and joint, joint
    limit, keypoint names; a door's hinge axis (a point on it and its direction), a drawer's pull
    axis and travel."""
    front = obj.front(k)
    record = {"index": k, "type": front.kind, "link_name": front.link_name,
              "joint_name": front.joint_name, "joint_type": front.joint_type,
              "joint_upper": front.joint_upper, "keypoint_names": list(front.keypoint_names)}
    if front.joint_type == "revolute":
        record["hinge_axis"] = {"point": list(front.p_OJ), "direction": list(front.axis_O)}
    else:
        record["pull_axis"] = list(front.axis_O)
        record["travel"] = front.joint_upper
    return record
