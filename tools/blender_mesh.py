"""Import a `bbsplat mesh` PLY with Blender's own importer, print its counts, optionally render it.

Run:
    blender --background --factory-startup --python tools/blender_mesh.py -- \
        mesh.ply [--render OUT.png] [--size 320] [--azimuth 30] [--elevation 25]

Prints one line `MESH vertices=V faces=F colours=C` (C: 1 when the importer found the vertex
colours) and, with --render, renders the mesh with the Workbench engine (studio light, vertex
colours) from a camera at the given azimuth and elevation (degrees, about world +Z after the
import, i.e. the PLY's own axes as Blender shows them) framing the mesh's bounding box, to
OUT.png (8-bit RGB, size × size).
"""

import math
import sys

import bpy
from mathutils import Vector


def parse_args(argv):
    args = argv[argv.index("--") + 1:] if "--" in argv else []
    if not args:
        sys.exit("usage: blender --background --python blender_mesh.py -- MESH.ply [--render OUT.png] [--size N]")
    options = {"ply": args[0], "render": None, "size": 320, "azimuth": 30.0, "elevation": 25.0, "up": "y"}
    rest = args[1:]
    while rest:
        flag = rest.pop(0)
        if flag == "--render":
            options["render"] = rest.pop(0)
        elif flag in ("--size",):
            options["size"] = int(rest.pop(0))
        elif flag in ("--azimuth", "--elevation"):
            options[flag[2:]] = float(rest.pop(0))
        elif flag == "--up":
            options["up"] = rest.pop(0)
        else:
            sys.exit(f"unknown option {flag}")
    return options


def main():
    options = parse_args(sys.argv)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_mesh.ply(filepath=options["ply"])
    objects = [o for o in bpy.context.scene.objects if o.type == "MESH"]
    if len(objects) != 1:
        sys.exit(f"expected one mesh object, found {len(objects)}")
    obj = objects[0]
    mesh = obj.data
    colours = 1 if len(mesh.vertex_colors) > 0 or len(getattr(mesh, "color_attributes", [])) > 0 else 0
    print(f"MESH vertices={len(mesh.vertices)} faces={len(mesh.polygons)} colours={colours}", flush=True)
    if options["render"] is None:
        return
    # The scenes' "up": y-up data (NeRF-synthetic is z-up, COLMAP arbitrary) is turned z-up.
    if options["up"] == "y":
        obj.rotation_euler = (math.pi / 2, 0.0, 0.0)
    elif options["up"] == "-y":
        obj.rotation_euler = (-math.pi / 2, 0.0, 0.0)
    bpy.context.view_layer.update()
    corners = [obj.matrix_world @ Vector(c) for c in obj.bound_box]
    lo = Vector((min(c[i] for c in corners) for i in range(3)))
    hi = Vector((max(c[i] for c in corners) for i in range(3)))
    centre = (lo + hi) / 2
    radius = (hi - lo).length / 2
    scene = bpy.context.scene
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.display.shading.light = "STUDIO"
    scene.display.shading.color_type = "VERTEX"
    scene.render.resolution_x = options["size"]
    scene.render.resolution_y = options["size"]
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode = "RGB"
    cam_data = bpy.data.cameras.new("camera")
    cam_data.lens = 50
    cam = bpy.data.objects.new("camera", cam_data)
    scene.collection.objects.link(cam)
    scene.camera = cam
    az, el = math.radians(options["azimuth"]), math.radians(options["elevation"])
    fov = cam_data.angle
    distance = radius / math.sin(fov / 2) * 1.05
    cam.location = centre + distance * Vector((math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)))
    direction = centre - cam.location
    cam.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
    cam_data.clip_end = distance * 4
    scene.render.filepath = options["render"]
    bpy.ops.render.render(write_still=True)
    print(f"RENDERED {options['render']}", flush=True)


main()
