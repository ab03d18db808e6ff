"""Render a `bbsplat export --format glb` file with Blender (Cycles) from one of its dataset cameras.

Run:
    blender --background --factory-startup --python tools/blender_check.py -- \
        planes_mesh.glb CAMERA OUT.png [--samples 64] [--raw]

CAMERA is the index of the camera in the glTF's `cameras` (the dataset's training views first,
then its test views, as `bbsplat export` writes them) or a camera name. The script:

1. imports the GLB with Blender's own glTF importer (geometry, UVs, the atlas and its alpha, the
   unlit material, the cameras);
2. makes the chosen camera the scene camera, with the dataset's exact intrinsics from the node's
   `extras` (focal length from fx, lens shift from the principal point) and its image size;
3. sets the world to the model's background colour (scene `extras`), the view transform to
   `Standard` (no filmic tone curve), and Cycles to enough transparent bounces to see through every
   layer of billboards (`transparent_max_bounces` 1024), a tight pixel filter (centre sampling,
   as the renderer), no denoising;
4. renders to OUT.png (8-bit RGB).

With --raw the material is rewired so that colours are not converted: the atlas is read as
Non-Color data and the view transform is `Raw`, i.e. blending happens on the stored 8-bit values
as in the bbsplat renderer. Without it the importer's material is used as is (glTF colour
textures are sRGB: Blender linearises them, blends in linear light and encodes the result back to
sRGB), which is what a user opening the file gets.

Compare with `bbsplat render` of the same camera (docs/export.md), e.g.
    cargo run --release --features examples --example compare_images -- OUT.png RENDER.png --side-by-side both.png
"""

import json
import math
import struct
import sys

import bpy


def parse_args(argv):
    args = argv[argv.index("--") + 1:] if "--" in argv else []
    if len(args) < 3:
        sys.exit("usage: blender --background --python blender_check.py -- GLB CAMERA OUT.png [--samples N] [--raw]")
    options = {"glb": args[0], "camera": args[1], "out": args[2], "samples": 64, "raw": False}
    rest = args[3:]
    while rest:
        flag = rest.pop(0)
        if flag == "--samples":
            options["samples"] = int(rest.pop(0))
        elif flag == "--raw":
            options["raw"] = True
        else:
            sys.exit(f"unknown option {flag}")
    return options


def read_gltf_json(path):
    with open(path, "rb") as f:
        header = f.read(20)
        magic, version, _total, json_len, json_type = struct.unpack("<IIIII", header)
        if magic != 0x46546C67 or version != 2 or json_type != 0x4E4F534A:
            sys.exit(f"{path}: not a glTF 2.0 binary")
        return json.loads(f.read(json_len))


def camera_nodes(doc):
    """(node, camera index) of every camera node, in camera index order."""
    nodes = [n for n in doc.get("nodes", []) if "camera" in n]
    return sorted(nodes, key=lambda n: n["camera"])


def find_object(name):
    for obj in bpy.data.objects:
        if obj.type == "CAMERA" and (obj.name == name or obj.data.name == name):
            return obj
    # The importer shortens names to Blender's 63 bytes.
    for obj in bpy.data.objects:
        if obj.type == "CAMERA" and name.startswith(obj.name):
            return obj
    sys.exit(f"camera {name!r} not found after import")


def rewire_raw(material):
    """Atlas colour straight to an emission shader, atlas alpha to a transparency mix."""
    nodes, links = material.node_tree.nodes, material.node_tree.links
    images = [n for n in nodes if n.type == "TEX_IMAGE"]
    if not images:
        sys.exit(f"material {material.name}: no image texture after import")
    tex = images[0]
    tex.image.colorspace_settings.name = "Non-Color"
    tex.interpolation = "Linear"
    keep = {tex.name} | {n.name for n in nodes if n.type == "UVMAP"}
    for name in [n.name for n in nodes if n.name not in keep]:
        nodes.remove(nodes[name])
    emission = nodes.new("ShaderNodeEmission")
    emission.inputs["Strength"].default_value = 1.0
    transparent = nodes.new("ShaderNodeBsdfTransparent")
    mix = nodes.new("ShaderNodeMixShader")
    out = nodes.new("ShaderNodeOutputMaterial")
    links.new(tex.outputs["Color"], emission.inputs["Color"])
    links.new(tex.outputs["Alpha"], mix.inputs["Fac"])
    links.new(transparent.outputs["BSDF"], mix.inputs[1])
    links.new(emission.outputs["Emission"], mix.inputs[2])
    links.new(mix.outputs["Shader"], out.inputs["Surface"])


def main():
    options = parse_args(sys.argv)
    doc = read_gltf_json(options["glb"])
    cams = camera_nodes(doc)
    if not cams:
        sys.exit(f"{options['glb']}: no camera")
    key = options["camera"]
    if key.isdigit():
        index = int(key)
        if index >= len(cams):
            sys.exit(f"camera {index} out of range ({len(cams)} cameras)")
        node = cams[index]
    else:
        matching = [n for n in cams if n.get("name") == key]
        if not matching:
            sys.exit(f"no camera named {key!r}")
        node = matching[0]
    extras = node["extras"]
    width, height = extras["width"], extras["height"]
    background = doc["scenes"][0].get("extras", {}).get("background", [0.0, 0.0, 0.0])

    bpy.ops.wm.read_factory_settings(use_empty=True)
    # Flat shading (the planes are unlit anyway); it also avoids the importer's `np.bool`, which
    # Debian's NumPy 1.24 no longer has (Blender 3.4's "NORMALS" shading path uses it).
    bpy.ops.import_scene.gltf(filepath=options["glb"], import_shading="FLAT")
    scene = bpy.context.scene

    obj = find_object(node["name"])
    scene.camera = obj
    cam = obj.data
    cam.sensor_fit = "HORIZONTAL"
    cam.sensor_width = 36.0
    cam.lens = extras["fx"] * cam.sensor_width / width
    # Lens shift in units of the larger image side; +x moves the window right, +y up.
    side = max(width, height)
    cam.shift_x = -(extras["cx"] - width / 2) / side
    cam.shift_y = (extras["cy"] - height / 2) / side
    cam.clip_start = 0.2
    cam.clip_end = 1e4
    if abs(extras["fx"] - extras["fy"]) > 1e-3 * extras["fx"]:
        scene.render.pixel_aspect_x = 1.0
        scene.render.pixel_aspect_y = extras["fx"] / extras["fy"]

    scene.render.resolution_x = width
    scene.render.resolution_y = height
    scene.render.resolution_percentage = 100
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = options["samples"]
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.use_denoising = False
    scene.cycles.pixel_filter_type = "BOX"
    scene.cycles.filter_width = 0.01
    scene.cycles.max_bounces = 1024
    scene.cycles.transparent_max_bounces = 1024
    scene.cycles.seed = 0
    scene.render.film_transparent = False

    world = bpy.data.worlds.new("background")
    world.use_nodes = True
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (*background, 1.0)
    bg.inputs["Strength"].default_value = 1.0
    scene.world = world

    if options["raw"]:
        for material in bpy.data.materials:
            if material.use_nodes:
                rewire_raw(material)
        scene.view_settings.view_transform = "Raw"
    else:
        scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode = "RGB"
    scene.render.image_settings.color_depth = "8"
    scene.render.filepath = options["out"]
    bpy.ops.render.render(write_still=True)
    print(f"blender_check: rendered camera {node['name']!r} ({width}x{height}, {options['samples']} samples, "
          f"{'raw' if options['raw'] else 'importer material'}) to {options['out']}")


main()
