#!/usr/bin/env python3
"""Undo a folded COLMAP registration of an orbit video: a copy of the scene in which each pass is
turned back to where the video's continuity says it was.

Usage: tools/colmap_unfold.py SRC_SCENE OUT_SCENE [--keep]

When a camera circles a nearly symmetric object (a can on a square-tiled floor), COLMAP can
register the far half of the orbit on top of the near half, turned by about 180 degrees about the
object's axis: every image then fits its own points, but two views that COLMAP puts side by side
see opposite sides of the room (docs/quality.md, "beer_colmap: the registration is folded").

The images are taken in name order as video frames. A *pass* starts wherever two consecutive
frames turn by more than 90 degrees (a phone cannot turn that far between two frames). At each
such boundary the first frame of the new pass is compared with the pose extrapolated from the last
two frames of the previous one (constant turn per frame); the rotation between them is the fold.
The folds' mean axis is the object's axis; the pivot is the point nearest to every camera's
optical axis (what the orbit looks at). Each pass after the first is then turned about that line
by the angle (searched every 0.25 degrees) that brings its first frame closest to the pose
extrapolated from the previous, already corrected, pass. 3D points seen by one pass only move
with it; points whose track spans passes are dropped (they join two folded halves).

With --keep the poses are written unchanged (the same points dropped), as the control of an
experiment. OUT_SCENE gets `sparse/0/{cameras,images,points3D}.txt` (COLMAP's text layout;
intrinsics copied) and `images` as a symbolic link to the source's. Binary models only (what
`colmap mapper` writes). No dependency beyond the standard library.
"""

import math
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
# A new pass starts where consecutive frames turn by more than this (degrees).
PASS_TURN_DEG = 90.0
# Step of the search for each pass's turn (degrees).
SEARCH_STEP_DEG = 0.25


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


# 3-vectors and 3x3 matrices (row-major tuples of rows).
def dot(a, b):
    return sum(x * y for x, y in zip(a, b))


def add(a, b):
    return [x + y for x, y in zip(a, b)]


def sub(a, b):
    return [x - y for x, y in zip(a, b)]


def scale(a, s):
    return [x * s for x in a]


def norm(a):
    return math.sqrt(dot(a, a))


def matmul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def transpose(a):
    return [[a[j][i] for j in range(3)] for i in range(3)]


def apply(a, v):
    return [dot(row, v) for row in a]


def solve3(a, b):
    """Solves a x = b by Cramer's rule."""
    def det(m):
        return (m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
                - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
                + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]))
    d = det(a)
    out = []
    for c in range(3):
        m = [row[:] for row in a]
        for r in range(3):
            m[r][c] = b[r]
        out.append(det(m) / d)
    return out


def quat_to_matrix(q):
    w, x, y, z = q
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]


def matrix_to_quat(r):
    w = math.sqrt(max(0.0, 1 + r[0][0] + r[1][1] + r[2][2])) / 2
    x = math.copysign(math.sqrt(max(0.0, 1 + r[0][0] - r[1][1] - r[2][2])) / 2, r[2][1] - r[1][2])
    y = math.copysign(math.sqrt(max(0.0, 1 - r[0][0] + r[1][1] - r[2][2])) / 2, r[0][2] - r[2][0])
    z = math.copysign(math.sqrt(max(0.0, 1 - r[0][0] - r[1][1] + r[2][2])) / 2, r[1][0] - r[0][1])
    return [w, x, y, z]


def angle_between(a, b):
    """Angle (radians) of the rotation a·bᵀ."""
    m = matmul(a, transpose(b))
    return math.acos(max(-1.0, min(1.0, (m[0][0] + m[1][1] + m[2][2] - 1) / 2)))


def axis_angle(m):
    angle = math.acos(max(-1.0, min(1.0, (m[0][0] + m[1][1] + m[2][2] - 1) / 2)))
    axis = [m[2][1] - m[1][2], m[0][2] - m[2][0], m[1][0] - m[0][1]]
    if norm(axis) < 1e-9:
        # Near 180 degrees the antisymmetric part vanishes: the axis is the column of
        # (m + I)/2 with the largest norm.
        cols = [[(m[r][c] + (1 if r == c else 0)) / 2 for r in range(3)] for c in range(3)]
        axis = max(cols, key=norm)
    return angle, scale(axis, 1 / norm(axis))


def rotation_about(axis, angle):
    k = [[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]]
    kk = matmul(k, k)
    s, c = math.sin(angle), 1 - math.cos(angle)
    return [[(1 if i == j else 0) + s * k[i][j] + c * kk[i][j] for j in range(3)] for i in range(3)]


def read_model(sparse):
    cams = []
    r = Reader(sparse / "cameras.bin")
    for _ in range(r.take("Q")[0]):
        cid, model, w, h = r.take("iiQQ")
        cams.append((cid, model, w, h, r.take(f"{PARAMS[model]}d")))
    images = []
    r = Reader(sparse / "images.bin")
    for _ in range(r.take("Q")[0]):
        iid = r.take("i")[0]
        q = r.take("4d")
        t = r.take("3d")
        cid = r.take("i")[0]
        name = r.name()
        n = r.take("Q")[0]
        r.at += n * 24  # 2D points (x, y, point3D_id) are not needed
        rot = quat_to_matrix(q)
        centre = scale(apply(transpose(rot), t), -1)
        images.append({"id": iid, "rot": rot, "centre": centre, "camera": cid, "name": name})
    points = []
    r = Reader(sparse / "points3D.bin")
    for _ in range(r.take("Q")[0]):
        pid = r.take("Q")[0]
        xyz = list(r.take("3d"))
        rgb = r.take("3B")
        err = r.take("d")[0]
        n = r.take("Q")[0]
        track = r.take(f"{2 * n}i")
        points.append((pid, xyz, rgb, err, [track[2 * j] for j in range(n)]))
    return cams, images, points


def extrapolated(a, b):
    """The pose after b if the frames keep turning and moving as from a to b."""
    rot = matmul(matmul(b["rot"], transpose(a["rot"])), b["rot"])
    return rot, add(b["centre"], sub(b["centre"], a["centre"]))


def main(argv):
    if len(argv) not in (3, 4) or (len(argv) == 4 and argv[3] != "--keep"):
        print(__doc__, file=sys.stderr)
        return 2
    src, out, keep = Path(argv[1]), Path(argv[2]), len(argv) == 4
    cams, images, points = read_model(src / "sparse" / "0")
    images.sort(key=lambda im: im["name"])
    passes = [[0]]
    for i in range(1, len(images)):
        if math.degrees(angle_between(images[i]["rot"], images[i - 1]["rot"])) > PASS_TURN_DEG:
            passes.append([])
        passes[-1].append(i)
    print("passes:", ", ".join(f"{images[p[0]]['name']}-{images[p[-1]]['name']}" for p in passes))
    # The pivot: least squares over the optical axes (I - f fᵀ)(x - c) = 0.
    a = [[0.0] * 3 for _ in range(3)]
    b = [0.0] * 3
    for im in images:
        f = apply(transpose(im["rot"]), [0.0, 0.0, 1.0])
        p = [[(1 if i == j else 0) - f[i] * f[j] for j in range(3)] for i in range(3)]
        a = [[a[i][j] + p[i][j] for j in range(3)] for i in range(3)]
        b = add(b, apply(p, im["centre"]))
    pivot = solve3(a, b)
    # The folds at the boundaries, and their mean axis (signs aligned with the first).
    axis_sum = [0.0] * 3
    for k in range(1, len(passes)):
        rot, _ = extrapolated(images[passes[k - 1][-2]], images[passes[k - 1][-1]])
        angle, axis = axis_angle(matmul(transpose(rot), images[passes[k][0]]["rot"]))
        if dot(axis, axis_sum) < 0:
            axis = scale(axis, -1)
        axis_sum = add(axis_sum, axis)
        print(f"boundary {k}: the fold turns {math.degrees(angle):.2f} deg about "
              f"({axis[0]:.3f}, {axis[1]:.3f}, {axis[2]:.3f})")
    if len(passes) == 1:
        print("one pass: nothing to unfold")
        axis = [0.0, 0.0, 1.0]
    else:
        axis = scale(axis_sum, 1 / norm(axis_sum))
    turns = [0.0]
    for k in range(1, len(passes)):
        rot_pred, centre_pred = extrapolated(images[passes[k - 1][-2]], images[passes[k - 1][-1]])
        first = images[passes[k][0]]
        steps = int(round(360 / SEARCH_STEP_DEG))
        err, turn = min(
            (angle_between(matmul(first["rot"], transpose(rotation_about(axis, th))), rot_pred), th)
            for th in (math.radians(s * SEARCH_STEP_DEG) for s in range(steps))
        )
        if keep:
            turn = 0.0
        else:
            t = rotation_about(axis, turn)
            for i in passes[k]:
                im = images[i]
                im["rot"] = matmul(im["rot"], transpose(t))
                im["centre"] = add(pivot, apply(t, sub(im["centre"], pivot)))
        turns.append(turn)
        gap = norm(sub(images[passes[k][0]]["centre"], centre_pred))
        print(f"pass {k + 1}: turned {math.degrees(turn):.2f} deg; first frame "
              f"{math.degrees(err):.2f} deg and {gap:.2f} units from the extrapolated pose")
    sparse = out / "sparse" / "0"
    sparse.mkdir(parents=True, exist_ok=True)
    with open(sparse / "cameras.txt", "w") as f:
        for cid, model, w, h, params in cams:
            f.write(f"{cid} {NAMES[model]} {w} {h} " + " ".join(f"{v:.17g}" for v in params) + "\n")
    with open(sparse / "images.txt", "w") as f:
        for im in images:
            q = matrix_to_quat(im["rot"])
            t = scale(apply(im["rot"], im["centre"]), -1)
            f.write(f"{im['id']} " + " ".join(f"{v:.17g}" for v in q + t) + f" {im['camera']} {im['name']}\n\n")
    pass_of = {images[i]["id"]: k for k, p in enumerate(passes) for i in p}
    kept = 0
    with open(sparse / "points3D.txt", "w") as f:
        for pid, xyz, rgb, err, track in points:
            owners = {pass_of[i] for i in track if i in pass_of}
            if len(owners) != 1:
                continue
            k = owners.pop()
            xyz = add(pivot, apply(rotation_about(axis, turns[k]), sub(xyz, pivot)))
            f.write(f"{pid} " + " ".join(f"{v:.17g}" for v in xyz) + f" {rgb[0]} {rgb[1]} {rgb[2]} {err:.17g}\n")
            kept += 1
    link = out / "images"
    if not link.exists():
        os.symlink((src / "images").resolve(), link)
    print(f"{len(images)} images, {kept} of {len(points)} points (tracks within one pass) -> {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
