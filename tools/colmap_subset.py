#!/usr/bin/env python3
"""A COLMAP scene restricted to some of its images, for experiments on parts of a capture.

Usage: tools/colmap_subset.py SRC_SCENE OUT_SCENE FIRST-LAST [FIRST-LAST ...]

SRC_SCENE is a COLMAP folder with `sparse/0/{cameras,images,points3D}.bin` and `images/`.
The ranges are image numbers (the first four characters of an image's name, `0036.jpg` is 36),
inclusive. OUT_SCENE gets `sparse/0/{cameras,images,points3D}.txt` in COLMAP's text layout with
only those images and their cameras, the 3D points whose track keeps at least two of them
(tracks cut to them), and `images` as a symbolic link to the source's. `bbsplat train OUT_SCENE
--test-every 0` then trains on all of them; `bbsplat eval MODEL OUT_SCENE --split train
--test-every 0` scores them (docs/quality-log.md, "beer_colmap: the capture's views disagree").
Poses, intrinsics and points are copied unchanged. No dependency beyond the standard library.
"""

import os
import struct
import sys
from pathlib import Path

PARAMS = {0: 3, 1: 4, 2: 4, 3: 5, 4: 8, 5: 8, 6: 12, 7: 5, 8: 4, 9: 5, 10: 12}
NAMES = {
    0: "SIMPLE_PINHOLE", 1: "PINHOLE", 2: "SIMPLE_RADIAL", 3: "RADIAL", 4: "OPENCV",
    5: "OPENCV_FISHEYE", 6: "FULL_OPENCV", 7: "FOV", 8: "SIMPLE_RADIAL_FISHEYE",
    9: "RADIAL_FISHEYE", 10: "THIN_PRISM_FISHEYE",
}


class Reader:
    def __init__(self, path):
        self.data = Path(path).read_bytes()
        self.at = 0

    def take(self, fmt):
        values = struct.unpack_from("<" + fmt, self.data, self.at)
        self.at += struct.calcsize("<" + fmt)
        return values

    def name(self):
        end = self.data.index(b"\0", self.at)
        text = self.data[self.at:end].decode()
        self.at = end + 1
        return text


def number(name):
    return int(name[:4])


def main(argv):
    if len(argv) < 4:
        sys.exit(__doc__)
    src, out = Path(argv[1]), Path(argv[2])
    keep = set()
    for r in argv[3:]:
        first, last = (int(x) for x in r.split("-"))
        keep.update(range(first, last + 1))
    sparse = src / "sparse" / "0"

    images = []
    r = Reader(sparse / "images.bin")
    for _ in range(r.take("Q")[0]):
        image_id, qw, qx, qy, qz, tx, ty, tz, camera_id = r.take("i7di")
        name = r.name()
        count = r.take("Q")[0]
        points2d = [r.take("ddq") for _ in range(count)]
        if number(name) in keep:
            images.append((image_id, (qw, qx, qy, qz, tx, ty, tz), camera_id, name, points2d))
    image_ids = {im[0] for im in images}
    camera_ids = {im[2] for im in images}

    (out / "sparse" / "0").mkdir(parents=True, exist_ok=True)
    if not (out / "images").exists():
        os.symlink((src / "images").resolve(), out / "images")

    r = Reader(sparse / "cameras.bin")
    with open(out / "sparse" / "0" / "cameras.txt", "w") as f:
        for _ in range(r.take("Q")[0]):
            camera_id, model, width, height = r.take("iiQQ")
            params = r.take("d" * PARAMS[model])
            if camera_id in camera_ids:
                f.write(f"{camera_id} {NAMES[model]} {width} {height} {' '.join(repr(p) for p in params)}\n")

    with open(out / "sparse" / "0" / "images.txt", "w") as f:
        for image_id, pose, camera_id, name, points2d in images:
            f.write(f"{image_id} {' '.join(repr(v) for v in pose)} {camera_id} {name}\n")
            f.write(" ".join(f"{x!r} {y!r} {pid}" for x, y, pid in points2d) + "\n")

    kept = 0
    r = Reader(sparse / "points3D.bin")
    with open(out / "sparse" / "0" / "points3D.txt", "w") as f:
        for _ in range(r.take("Q")[0]):
            point_id, x, y, z, red, green, blue, error, length = r.take("Q3d3BdQ")
            track = [r.take("ii") for _ in range(length)]
            track = [(i, k) for i, k in track if i in image_ids]
            if len(track) < 2:
                continue
            kept += 1
            elements = " ".join(f"{i} {k}" for i, k in track)
            f.write(f"{point_id} {x!r} {y!r} {z!r} {red} {green} {blue} {error!r} {elements}\n")
    print(f"{len(images)} images, {len(camera_ids)} cameras, {kept} points -> {out}")


if __name__ == "__main__":
    main(sys.argv)
