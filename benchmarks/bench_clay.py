"""How the clay follows a moved control: the figures the local restarts (somwidget/backend/som.py) are held to.

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

With `--drag N` it measures a drag instead: control 1 moved by 5% of the size in N steps, each a restart followed by
a frame's cycles (the whole restarted schedule, or 10 cycles), then the run to s = S; the far half's 90th percentile
when every step restarts from the latest weights, and when each restarts from the shape the drag began with (what
the session does).

    PYTHONPATH=. python benchmarks/bench_clay.py                     # every preset, the presets' own reach
    PYTHONPATH=. python benchmarks/bench_clay.py --reach 0.05 0.08 0.12 --presets car torus   # compare reach values
    PYTHONPATH=. python benchmarks/bench_clay.py --drag 30 --presets car torus sphere
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


def drag(name: str, steps: int, frame_cycles: int, rebase: bool, device: str = "cpu") -> tuple[float, float]:
    """(least size at any frame, far half's 90th percentile at the end) of a drag of control 1 by 5% in `steps`."""
    preset = presets.get_preset(name)
    som = shown_som(preset, device, None)
    dims = list(preset.layout.position)
    start = som.weights
    before = start[:, dims].astype(np.float64)
    size = metrics.bounding_diagonal(before)
    controls = som.controls
    origin = controls[1, dims].astype(np.float64)
    away = (origin - before.mean(axis=0)) / np.linalg.norm(origin - before.mean(axis=0))
    least = 1.0
    for i in range(1, steps + 1):
        controls[1, dims] = origin + away * 0.05 * size * i / steps
        if rebase:
            som.restore(start, som.iterations)
        som.set_controls(controls)
        som.step(frame_cycles)
        least = min(least, metrics.bounding_diagonal(som.weights[:, dims]) / size)
    som.train()
    mirrored = [dims.index(m) for m in som.mirror if m in dims]
    return least, metrics.far_half_moved(before, som.weights[:, dims], controls[1, dims], mirrored)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--presets", nargs="+", default=list(DEFAULT_PRESETS))
    parser.add_argument("--reach", nargs="+", type=float, default=[None])
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--drag", type=int, metavar="N", help="measure a drag in N steps instead (see above)")
    args = parser.parse_args(argv)
    if args.drag:
        print("| preset | restarts from | cycles a frame | least size | far p90 |")
        print("|---|---|---|---|---|")
        for name in args.presets:
            for rebase in (False, True):
                for cycles in (1_000_000, 10):
                    least, far = drag(name, args.drag, cycles, rebase, args.device)
                    origin = "the drag's start" if rebase else "the latest weights"
                    print(f"| {name} | {origin} | "
                          f"{'all' if cycles > 1000 else cycles} | {least:.3f} | {far:.4f} |", flush=True)
        return 0
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
