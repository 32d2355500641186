"""A long move of a point control on the car: how the restart's reach shapes the clay around it (schedule.py,
`reach_for_move`, MOVE_SPAN and MOVE_REACH_MOST).

The trained car; then one of five (control, direction) pairs moved by 0.3, 0.6, 0.9 and 1.2 model units (1.4 to 5.5
median edges) and run to s = S from a fresh copy each time, with the restart's reach max(0.08, min(most, span * h /
sigma)) for each rule given as span:most (span 0: the preset's 0.08 alone). Printed per rule, the worst and the mean
over the 20 moves:

  spike   the moved control's winner's distance to the mean of its one-ring over the median edge (a needle: ~1)
  gap     that winner's distance to the control, model units
  far     how far the half of the nodes farther from the control (and its mirror) moved, p90, over the size

    PYTHONPATH=. python benchmarks/bench_long_moves.py                       # the rules of the table in BENCHMARKS.md
    PYTHONPATH=. python benchmarks/bench_long_moves.py --rules 1.5:0.18 --details
"""

from __future__ import annotations

import argparse

import numpy as np

from somwidget.backend import metrics, presets
from somwidget.backend.schedule import sigma_of

#: (control, direction): the nose forward and up, the roof up, a wheel down, the tail back.
MOVES = [(2, (1, 0, 0)), (2, (0, 0, 1)), (4, (0, 0, 1)), (0, (0, 0, -1)), (3, (-1, 0, 0))]
DISTANCES = (0.3, 0.6, 0.9, 1.2)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rules", nargs="+",
                        default=["0:1", "1:1", "1.5:1", "2:1", "1.5:0.16", "1.5:0.18", "1.5:0.22"])
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--details", action="store_true", help="every move's figures")
    args = parser.parse_args()
    preset = presets.get_preset("car")
    trained = preset.make_som(args.device)
    trained.train()
    w0 = trained.weights.copy()
    topo = preset.topology
    edge = metrics.median_edge(w0[:, :3], topo.edges)
    sigma = sigma_of(topo.d_max)
    print(f"car: median edge {edge:.3f}, d_max {topo.d_max}, sigma {sigma:.2f}")
    print("| span:most | spike max / mean | gap max | far p90 max |")
    print("|---|---|---|---|")
    for rule in args.rules:
        span, most = (float(x) for x in rule.split(":"))
        rows = []
        for control, direction in MOVES:
            for distance in DISTANCES:
                reach = max(preset.reach, min(most, span * distance / edge / sigma))
                som = preset.make_som(args.device)
                som.restore(w0, som.iterations)
                som.reach = reach
                controls = som.controls.copy()
                controls[control, :3] += distance * np.asarray(direction, np.float32)
                before = som.weights[:, :3].astype(np.float64)
                som.set_controls(controls)
                som.train()
                after = som.weights[:, :3].astype(np.float64)
                target = controls[control, :3].astype(np.float64)
                winner = int(np.argmin(np.linalg.norm(after - target, axis=1)))
                rows.append((control, distance, reach, metrics.spike_figures(after, topo, [winner])[0],
                             float(np.linalg.norm(after[winner] - target)),
                             metrics.far_half_moved(before, after, target, [1])))
        a = np.asarray(rows)
        print(f"| {rule} | {a[:, 3].max():.2f} / {a[:, 3].mean():.2f} | {a[:, 4].max():.3f} | {a[:, 5].max():.4f} |")
        if args.details:
            for c, d, r, spike, gap, far in rows:
                print(f"    control {c} by {d}: reach {r:.3f} spike {spike:.2f} gap {gap:.3f} far {far:.4f}")


if __name__ == "__main__":
    main()
