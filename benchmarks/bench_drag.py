"""What a drag costs per frame: the app's frame while a control moves against its frame while the clay only trains.

Per drag event the session hands the moved controls to the Som (`set_controls`: a local restart from the shape the
drag began with, which `anchor` kept on the device), runs the frame's cycles (`step(k)`) and reads the weights for
the views; a plain frame only steps and reads. Both are timed the same way, frame after
frame, on one Som (the drag moves control 0 a little further each frame, as a hand does).

(At the session's level the two cannot be told apart this way: the session sizes each step to fill the frame's
time budget, and a drag frame's step is a quarter as long, to show the move sooner.)

The ratio drag / plain is what a person dragging pays over watching. Medians over the frames.

    PYTHONPATH=. python benchmarks/bench_drag.py [--device cuda:0] [--presets car space-grid] [--cycles 10]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

import numpy as np
import warp as wp

from somwidget.backend import presets


def frames(som, cycles: int, count: int, drag: bool) -> list[float]:
    """Seconds per frame: (when `drag`: the drag's start restored, set_controls with control 0 moved a step),
    step(cycles), the weights read."""
    controls = som.controls
    step = 0.002 * np.float32(np.abs(som.weights).max())
    som.anchor()
    out = []
    for _ in range(count):
        if som.iteration >= som.iterations:
            som.restart()
        wp.synchronize_device(som.device)
        t = time.perf_counter()
        if drag:
            controls[0, 0] += step
            som.set_controls(controls, from_anchor=True)
        som.step(cycles)
        wp.synchronize_device(som.device)
        _ = som.weights
        out.append(time.perf_counter() - t)
    return out


def measure(name: str, device: str, cycles: int, count: int) -> dict:
    som = presets.get_preset(name).make_som(device)
    som.train()
    frames(som, cycles, 20, True)  # warm-up: kernels loaded, graphs captured
    frames(som, cycles, 20, False)
    plain = statistics.median(frames(som, cycles, count, False))
    drag = statistics.median(frames(som, cycles, count, True))
    return {"preset": name, "device": device, "cycles": cycles, "plain_ms": plain * 1e3, "drag_ms": drag * 1e3,
            "ratio": drag / plain}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--presets", nargs="+", default=["car", "space-grid"])
    parser.add_argument("--cycles", type=int, default=10)
    parser.add_argument("--frames", type=int, default=200)
    args = parser.parse_args(argv)
    wp.config.quiet = True
    print(f"device {args.device} ({wp.get_device(args.device).name}), step({args.cycles}) a frame, "
          f"median of {args.frames} frames")
    print("| preset | plain frame (ms) | drag frame (ms) | drag / plain |")
    print("|---|---|---|---|")
    for name in args.presets:
        r = measure(name, args.device, args.cycles, args.frames)
        print(f"| {name} | {r['plain_ms']:.3f} | {r['drag_ms']:.3f} | {r['ratio']:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
