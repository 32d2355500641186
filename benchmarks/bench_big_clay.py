"""Big clay on the CPU (issue 28): what a drag frame costs as the mesh grows.

A drag frame is what the app does per drag event: `set_controls` with one control moved (a restart from the shape the
drag began with, `anchor`), `step(10)`, and the weights read back for the views. Each (case, size) runs in a fresh
process (its peak RSS is the figure); medians and 90th percentiles over the frames, wall time and the process's CPU
time (the machine is shared: CPU time is what the frame cost, wall time what it took).

Cases:
  paper   an open W x W grid (2 x 2 model units), six controls on it (presets.controls_on), the paper's point controls
          at reach 0.08, distance rows: the issue's measurement
  kept    the same grid kept as an upload is (presets.kept_shape: each control's radius a quarter of the size, reach
          0.3, Taubin's rule): what a CPU session does with an uploaded mesh
  brush   sheets 0.01 apart growing in extent (W x W), six controls of radius 0.05 model units on them, the one at the
          centre dragged: the region a drag touches stays the same while N grows
  tiles   W/64 x W/64 separate 64 x 64 tiles (an upload of many parts), six point controls at reach 0.08 on six tiles:
          the paper's rule touches the controls' tiles, whatever the number of tiles

Usage:
    PYTHONPATH=. python benchmarks/bench_big_clay.py [--cases paper,kept] [--sides 128,256,512] [--frames 40]
                                                     [--json out.json]
Needs numpy and warp-lang only.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time

import numpy as np

CASES = ("paper", "kept", "brush", "tiles")


def mesh(case: str, side: int):
    """(topology, start weights, controls, Som keywords, index of the dragged control) of a case."""
    from somwidget.backend.presets import controls_on, kept_shape, open_grid
    from somwidget.backend.topology import Topology

    if case == "tiles":
        tile, per = 64, max(1, side // 64)
        faces, pts = open_grid(tile, tile, size=0.63)
        all_faces, all_pts = [], []
        for t in range(per * per):
            offset = np.float32([(t % per) * 0.7, (t // per) * 0.7, 0.0])
            all_faces.append(faces + t * len(pts))
            all_pts.append(pts + offset)
        faces, pts = np.concatenate(all_faces), np.concatenate(all_pts)
        tiles = np.linspace(0, per * per - 1, 6).astype(int)
        controls = pts[tiles * tile * tile + tile * tile // 2 + tile // 2].copy()
        return Topology.from_faces(faces, len(pts)), pts, controls, {"reach": 0.08}, 2
    size = 0.01 * (side - 1) if case == "brush" else 2.0
    faces, pts = open_grid(side, side, size=size)
    pts[:, 2] = 0.02 * size * np.sin(7.0 * pts[:, 0] / size) * np.cos(5.0 * pts[:, 1] / size)
    controls = controls_on(pts)
    topo = Topology.from_faces(faces, len(pts))
    if case == "paper":
        return topo, pts, controls, {"reach": 0.08}, 2
    if case == "kept":
        kept = kept_shape(pts)
        return topo, pts, controls, {"reach": kept["reach"], "radii": [kept["radius"]] * len(controls),
                                     "smoothing_rule": kept["smoothing_rule"]}, 2
    return topo, pts, controls, {"reach": 0.3, "radii": [0.05] * len(controls), "smoothing_rule": "taubin"}, 0


def measure(case: str, side: int, frames: int, device: str) -> dict:
    import warp as wp

    from somwidget import Som

    wp.config.quiet = True
    topo, pts, controls, options, dragged = mesh(case, side)
    som = Som(topo, pts, controls, device=device, distances="rows", **options)
    som.restore(pts, som.iterations)  # a kept shape: nothing trains until a control moves
    som.anchor()
    moved = controls.copy()
    step = 0.002 * float(np.ptp(pts[:, 0]))

    def frame() -> tuple[float, float]:
        moved[dragged, 0] += step
        moved[dragged, 2] += 1.5 * step
        t, c = time.perf_counter(), time.process_time()
        som.set_controls(moved, from_anchor=True)
        som.step(10)
        _ = som.weights
        return time.perf_counter() - t, time.process_time() - c

    for _ in range(5):  # kernels loaded, the first rows searched
        frame()
    got = np.array([frame() for _ in range(frames)]) * 1e3
    wall, cpu = got[:, 0], got[:, 1]
    return {"case": case, "side": side, "nodes": int(topo.n_vertices), "device": som.device,
            "drag_ms_median": float(np.median(wall)), "drag_ms_p90": float(np.percentile(wall, 90)),
            "cpu_ms_median": float(np.median(cpu)), "cpu_ms_p90": float(np.percentile(cpu, 90)),
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", default="paper,kept")
    ap.add_argument("--sides", default="128,256,512")
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--json", default=None)
    ap.add_argument("--one", default=None, help=argparse.SUPPRESS)  # case:side, in this process
    args = ap.parse_args()
    if args.one:
        case, side = args.one.split(":")
        print(json.dumps(measure(case, int(side), args.frames, args.device)))
        return 0
    out = {"machine": platform.node(), "cpus": os.cpu_count(), "date": time.strftime("%Y-%m-%d"), "results": []}
    print("| case | nodes | drag frame median / p90 (ms) | CPU time a frame, median / p90 (ms) | peak RSS (MB) |")
    print("|---|---|---|---|---|")
    for case in args.cases.split(","):
        for side in (int(s) for s in args.sides.split(",")):
            run = subprocess.run([sys.executable, __file__, "--one", f"{case}:{side}", "--frames", str(args.frames),
                                  "--device", args.device], capture_output=True, text=True, check=True)
            r = json.loads(run.stdout.strip().splitlines()[-1])
            out["results"].append(r)
            print(f"| {case} | {r['nodes']:,} | {r['drag_ms_median']:.1f} / {r['drag_ms_p90']:.1f} | "
                  f"{r['cpu_ms_median']:.1f} / {r['cpu_ms_p90']:.1f} | {r['peak_rss_mb']:.0f} |", flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
