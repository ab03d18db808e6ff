#!/usr/bin/env python3
"""Test PSNR against training minutes, one line per run, from the runs' summary.json files.

Usage: tools/plot_curves.py OUT.svg LABEL=RUN_DIR [LABEL=RUN_DIR ...] [--title TEXT]

Each RUN_DIR is an output folder of `bbsplat train` (its `summary.json`). A line joins the
run's curve points (`curve`: step, seconds of steps, PSNR on the evaluation views); the final
figure (all test views, the saved 8-bit model) is drawn as a filled dot at the run's training
time, labelled with its PSNR. No dependency beyond the Python standard library.
"""

import json
import math
import sys
from pathlib import Path

COLOURS = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b"]
W, H = 720, 440
LEFT, RIGHT, TOP, BOTTOM = 64, 170, 40, 52


def load(run_dir):
    with open(Path(run_dir) / "summary.json") as f:
        s = json.load(f)
    s = s.get("summary", s)
    curve = [(p["seconds"] / 60.0, p["psnr"]) for p in s.get("curve", []) if p.get("psnr") is not None]
    final = (s["train_seconds"] / 60.0, s["test_psnr"])
    return curve, final


def ticks(lo, hi, target=6):
    raw = (hi - lo) / target
    mag = 10 ** math.floor(math.log10(raw))
    step = min((m * mag for m in (1, 2, 5, 10) if m * mag >= raw))
    t = math.ceil(lo / step) * step
    out = []
    while t <= hi + 1e-9:
        out.append(round(t, 10))
        t += step
    return out


def main(argv):
    title = None
    if "--title" in argv:
        i = argv.index("--title")
        title = argv[i + 1]
        argv = argv[:i] + argv[i + 2:]
    if len(argv) < 2:
        sys.exit(__doc__)
    out, runs = argv[0], []
    for arg in argv[1:]:
        label, _, run_dir = arg.partition("=")
        if not run_dir:
            sys.exit(f"expected LABEL=RUN_DIR, got {arg!r}")
        runs.append((label,) + load(run_dir))
    xs = [x for _, c, f in runs for x, _ in c + [f]]
    ys = [y for _, c, f in runs for _, y in c + [f]]
    x_lo, x_hi = 0.0, max(xs) * 1.03
    y_lo, y_hi = math.floor(min(ys) - 0.5), math.ceil(max(ys) + 0.5)
    pw, ph = W - LEFT - RIGHT, H - TOP - BOTTOM

    def px(x):
        return LEFT + (x - x_lo) / (x_hi - x_lo) * pw

    def py(y):
        return TOP + (1.0 - (y - y_lo) / (y_hi - y_lo)) * ph

    svg = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" font-family="sans-serif" font-size="12">',
           f'<rect width="{W}" height="{H}" fill="white"/>']
    for t in ticks(x_lo, x_hi):
        svg.append(f'<line x1="{px(t):.1f}" y1="{TOP}" x2="{px(t):.1f}" y2="{TOP + ph}" stroke="#ddd"/>')
        svg.append(f'<text x="{px(t):.1f}" y="{TOP + ph + 16}" text-anchor="middle">{t:g}</text>')
    for t in ticks(y_lo, y_hi):
        svg.append(f'<line x1="{LEFT}" y1="{py(t):.1f}" x2="{LEFT + pw}" y2="{py(t):.1f}" stroke="#ddd"/>')
        svg.append(f'<text x="{LEFT - 6}" y="{py(t) + 4:.1f}" text-anchor="end">{t:g}</text>')
    svg.append(f'<rect x="{LEFT}" y="{TOP}" width="{pw}" height="{ph}" fill="none" stroke="#333"/>')
    svg.append(f'<text x="{LEFT + pw / 2}" y="{H - 12}" text-anchor="middle">training time (minutes of steps)</text>')
    svg.append(f'<text x="16" y="{TOP + ph / 2}" text-anchor="middle" transform="rotate(-90 16 {TOP + ph / 2})">test PSNR (dB)</text>')
    if title:
        svg.append(f'<text x="{LEFT + pw / 2}" y="22" text-anchor="middle" font-size="14">{title}</text>')
    for k, (label, curve, final) in enumerate(runs):
        colour = COLOURS[k % len(COLOURS)]
        if curve:
            pts = " ".join(f"{px(x):.1f},{py(y):.1f}" for x, y in curve)
            svg.append(f'<polyline points="{pts}" fill="none" stroke="{colour}" stroke-width="2"/>')
            for x, y in curve:
                svg.append(f'<circle cx="{px(x):.1f}" cy="{py(y):.1f}" r="2.5" fill="{colour}"/>')
        fx, fy = final
        svg.append(f'<circle cx="{px(fx):.1f}" cy="{py(fy):.1f}" r="5" fill="{colour}" stroke="black"/>')
        svg.append(f'<text x="{px(fx) - 8:.1f}" y="{py(fy) - 9:.1f}" text-anchor="end" fill="{colour}">{fy:.2f}</text>')
        ly = TOP + 16 + 20 * k
        svg.append(f'<line x1="{LEFT + pw + 12}" y1="{ly - 4}" x2="{LEFT + pw + 36}" y2="{ly - 4}" stroke="{colour}" stroke-width="2"/>')
        svg.append(f'<text x="{LEFT + pw + 42}" y="{ly}">{label}</text>')
    svg.append(f'<text x="{LEFT + pw + 12}" y="{TOP + 16 + 20 * len(runs) + 6}" font-size="10">line: evaluation views</text>')
    svg.append(f'<text x="{LEFT + pw + 12}" y="{TOP + 16 + 20 * len(runs) + 20}" font-size="10">dot: final, all test views</text>')
    svg.append("</svg>")
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    Path(out).write_text("\n".join(svg) + "\n")


if __name__ == "__main__":
    main(sys.argv[1:])
