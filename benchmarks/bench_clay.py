"""How the clay follows a moved control: the figures DESIGN.md's local restarts are held to, per preset.

For each preset: the shape a session shows (the paper's case studies trained by their whole schedule; the general
shapes as they are), then each control in turn moved by 5% of the shape's size away from its centroid and followed
to s = S in frames of 10 cycles, from a fresh copy each time. Printed per preset, the worst over its controls:

  least size   the smallest bounding diagonal at any frame, over the one before the move (no collapse: >= 0.90)
  far p90      how far the half of the nodes farther from the moved control (and its mirror) moved, 90th percentile,
               as a share of the size (the rest of the shape stays: <= 0.02)
  gap          the moved control's distance to its nearest node at the end, over the size (it is followed: <= 0.01)
  spike        the winners' largest spike figure at the end: distance to the mean of the one-ring over the median
               edge length (a needle drawn out to a control shows as several)
  symmetry     for mirrored presets, after the case study's run: the largest mirror mismatch over the size

    PYTHONPATH=. python benchmarks/bench_clay.py                     # every preset, the presets' own reach
    PYTHONPATH=. python benchmarks/bench_clay.py --reach 0.05 0.08 0.12 --presets car torus   # compare reach values
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from somwidget.backend import metrics, presets

#: Presets measured by default: the issue's three first.
DEFAULT_PRESETS = ("car", "space-grid", "torus", "sphere", "grid", "lattice", "lines")


def shown_som(preset: presets.Preset, device: str, reach: float | None):
    """The Som as a session shows the preset: a case study trained, a general shape as it is (s = S)."""
    som = preset.make_som(device)
    if reach is not None:
        som.reach = reach
    if preset.grow:
        som.train()
    else:
        som.restore(preset.weights, som.iterations)
    return som


def measure(name: str, device: str = "cpu", reach: float | None = None, controls=None) -> dict:
    preset = presets.get_preset(name)
    start = shown_som(preset, device, reach)
    weights, iteration = start.weights, start.iteration
    symmetry = float("nan")
    if preset.mirror:
        pos = weights[:, list(preset.layout.position)]
        symmetry = metrics.symmetry_error(pos, metrics.mirror_map(preset.weights[:, list(preset.layout.position)]))
    worst = {"least_size": 1.0, "far_moved_p90": 0.0, "gap": 0.0, "spike": 0.0}
    chosen = range(len(preset.controls)) if controls is None else controls
    for c in chosen:
        start.restore(weights, iteration)
        start.set_controls(preset.controls)
        start.restore(weights, iteration)
        f = metrics.follow(start, c, position_dims=preset.layout.position)
        worst["least_size"] = min(worst["least_size"], f.least_size)
        worst["far_moved_p90"] = max(worst["far_moved_p90"], f.far_moved_p90)
        worst["gap"] = max(worst["gap"], f.gap)
        worst["spike"] = max(worst["spike"], f.spike)
    return {"preset": name, "reach": start.reach, "controls": len(list(chosen)), "symmetry": symmetry, **worst}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--presets", nargs="+", default=list(DEFAULT_PRESETS))
    parser.add_argument("--reach", nargs="+", type=float, default=[None])
    parser.add_argument("--device", default="cpu")
    args = parser.parse_args(argv)
    print("| preset | reach | controls | least size | far p90 | gap | spike | symmetry | s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in args.presets:
        for reach in args.reach:
            t = time.perf_counter()
            r = measure(name, args.device, reach)
            print(f"| {r['preset']} | {r['reach']:.3g} | {r['controls']} | {r['least_size']:.3f} | "
                  f"{r['far_moved_p90']:.4f} | {r['gap']:.4f} | {r['spike']:.2f} | "
                  f"{'' if np.isnan(r['symmetry']) else format(r['symmetry'], '.1e')} | "
                  f"{time.perf_counter() - t:.0f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
