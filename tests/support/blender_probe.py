"""Run by tests/unit/test_blender.py in Blender's Python (the bpy module of ``.venv-blender``, made by
``make setup``): import a glTF and OBJ files with Blender's bundled importers, default settings,
and print what a Blender user gets as JSON on the last line of stdout.

Usage: ``python blender_probe.py request.json``, the request holding ``glb`` (a path), ``poses``
(a list of {shape key: value}) and ``objs`` (a list of paths). For the glTF: the shape keys
(name, slider range, the value Blender keeps when asked for -1 and 3) and the evaluated world
positions of the mesh at each pose; for each OBJ: world positions, polygon count, the vertices no
polygon uses, the material's image (file name, size) and the UV layers.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import bpy


def _world(obj) -> list[list[float]]:
    """World positions of the evaluated mesh (modifiers and shape keys applied)."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    evaluated = obj.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    matrix = obj.matrix_world
    out = [list(matrix @ v.co) for v in mesh.vertices]
    evaluated.to_mesh_clear()
    return out


def _only_mesh(before: set[str]):
    new = [o for o in bpy.data.objects if o.name not in before and o.type == "MESH"]
    if len(new) != 1:
        raise SystemExit(f"expected one imported mesh object, got {[o.name for o in new]}")
    return new[0]


def probe_glb(path: str, poses: list[dict]) -> dict:
    before = {o.name for o in bpy.data.objects}
    result = bpy.ops.import_scene.gltf(filepath=path)
    obj = _only_mesh(before)
    blocks = obj.data.shape_keys.key_blocks
    keys = [{"name": k.name, "min": k.slider_min, "max": k.slider_max} for k in blocks]
    clamps = {}
    for key in blocks[1:]:  # what Blender keeps of values beyond the range, from Python
        kept = []
        for value in (-1.0, 3.0):
            key.value = value
            kept.append(key.value)
        clamps[key.name] = kept
        key.value = 0.0
    shapes = []
    for pose in poses:
        for key in blocks[1:]:
            key.value = float(pose.get(key.name, 0.0))
        bpy.context.view_layer.update()
        shapes.append(_world(obj))
    return {
        "result": sorted(result),
        "object": obj.name,
        "keys": keys,
        "clamps": clamps,
        "shapes": shapes,
        "materials": [m.name for m in obj.data.materials],
        "uv_layers": list(obj.data.uv_layers.keys()),
    }


def probe_obj(path: str) -> dict:
    before = {o.name for o in bpy.data.objects}
    result = bpy.ops.wm.obj_import(filepath=path)
    obj = _only_mesh(before)
    mesh = obj.data
    used = set()
    for poly in mesh.polygons:
        used.update(poly.vertices)
    images = []
    for mat in mesh.materials:
        for node in mat.node_tree.nodes if mat and mat.node_tree else []:
            if node.type == "TEX_IMAGE" and node.image is not None:
                images.append([Path(node.image.filepath).name, list(node.image.size)])
    return {
        "result": sorted(result),
        "world": _world(obj),
        "polygons": len(mesh.polygons),
        "loose": sorted(set(range(len(mesh.vertices))) - used),
        "images": images,
        "uv_layers": list(mesh.uv_layers.keys()),
    }


def main() -> None:
    request = json.loads(Path(sys.argv[-1]).read_text())
    bpy.ops.wm.read_factory_settings(use_empty=True)
    out = {"version": bpy.app.version_string}
    if request.get("glb"):
        out["glb"] = probe_glb(request["glb"], request.get("poses", []))
    out["objs"] = [probe_obj(p) for p in request.get("objs", [])]
    print(json.dumps(out))


if __name__ == "__main__":
    main()
