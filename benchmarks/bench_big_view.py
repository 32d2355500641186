"""Big meshes in the clay view, measured where they train (a GPU machine, no browser): what the views' server side
does per frame for an open W x W grid shown as it is, with its 6 controls on it, one view attached (a thread that
takes every frame from the session's outbox, encoded, as the websocket hub's sender does).

For each size it reports:
  topology   the topology message (the decimated display mesh past wire_display.STREAM_LIMIT nodes): time, bytes
  frame      encoding one frame for the views: time, bytes (what every view receives per frame)
  training   frames the session publishes per second while the schedule runs from Reset (the whole run, or its
             first --train-seconds), and cycles per second
  drag       a drag of one control, a move every 1/30 s for 2 s inside one gesture: frames published per second,
             and move -> first published frame showing the control there (median, 90th percentile); the view's
             frames per second over the drag

Usage:
    PYTHONPATH=. python benchmarks/bench_big_view.py [--sides 256,1000] [--device cuda:0] [--train-seconds 10]
                                                     [--json out.json]

Needs numpy and warp-lang only (the Session and the protocol import nothing else), so it runs on the GPU machine.
"""

from __future__ import annotations

import argparse
import json
import platform
import resource
import sys
import threading
import time

import numpy as np

from somwidget.backend.presets import XYZ, Preset, controls_on, open_grid
from somwidget.backend.topology import Topology
from somwidget.frontend.model import Session
from somwidget.frontend.transport import display as wire_display
from somwidget.frontend.transport import frames as wire_frames
from somwidget.frontend.transport.outbox import Peer, outbox_for


def grid(side: int) -> Preset:
    faces, pts = open_grid(side, side)
    return Preset(name=f"grid-{side}", title=f"Grid {side} x {side}", description="an open quad sheet",
                  topology=Topology.from_faces(faces, len(pts)), weights=pts, controls=controls_on(pts), layout=XYZ,
                  reach=0.06)


class Watch:
    """Frames the session publishes: when each arrived and its controls (not the frame: a million nodes' weights a
    frame would fill the memory the benchmark measures)."""

    def __init__(self, session: Session):
        self.frames: list[tuple[float, np.ndarray]] = []
        self.lock = threading.Lock()
        session.add_listener(self.on_frame, replay=False)

    def on_frame(self, frame) -> None:
        with self.lock:
            self.frames.append((time.perf_counter(), np.array(frame.controls)))

    def since(self, t0: float) -> list:
        with self.lock:
            return [(t, c) for t, c in self.frames if t >= t0]


class View(threading.Thread):
    """A view of the session: wakes on each published frame and takes its packets from the outbox (the frame
    encoded), as the websocket hub's sender does; keeps when each frame went out."""

    def __init__(self, session: Session):
        super().__init__(daemon=True)
        self.outbox, self.peer = outbox_for(session), Peer()
        self.wake, self.stop, self.sent = threading.Event(), False, []
        self.outbox.subscribe(self.wake.set)

    def run(self) -> None:
        while not self.stop:
            if self.wake.wait(0.1):
                self.wake.clear()
                if self.outbox.packets(self.peer):
                    self.sent.append(time.perf_counter())

    def close(self) -> None:
        self.stop = True
        self.outbox.unsubscribe(self.wake.set)
        self.join(5)


def measure(side: int, device: str, train_seconds: float) -> dict:
    t = time.perf_counter()
    preset = grid(side)
    session = Session(preset, device=device, autosave=False)
    made = time.perf_counter() - t
    view = None
    try:
        session.wait_idle(600)
        frame = session.frame
        t = time.perf_counter()
        topo = wire_display.topology_message(session, frame)
        topo_s = time.perf_counter() - t
        topo_bytes = len(json.dumps(topo.to_json()))
        t = time.perf_counter()
        for _ in range(10):
            data = wire_frames.encode_frame(frame, session)
        encode_s = (time.perf_counter() - t) / 10
        watch = Watch(session)
        view = View(session)
        view.start()
        t0 = time.perf_counter()
        session.reset()  # the whole schedule from the start mesh (or its first train_seconds)
        cut = not session.wait_idle(train_seconds)
        if cut:
            session.pause()
            session.wait_idle(60)
        run = watch.since(t0)
        run_s = run[-1][0] - t0 if run else float("nan")
        cycles = session.frame.iteration  # from s = 0
        if cut:  # back to the settled shape (undo the reset), trained on to S from there: the drag starts settled
            session.undo()
            session.train()
            session.wait_idle(600)
        i = 2
        start = np.array(session.controls[i][:3], np.float64)
        moves, latencies = [], []
        with session.gesture():
            t0 = time.perf_counter()
            for k in range(1, 61):
                p = start + np.array([0.004 * k, 0.0, 0.006 * k])
                sent = time.perf_counter()
                session.move_control(i, p.tolist())
                moves.append((sent, p.astype(np.float32)))
                time.sleep(max(0.0, t0 + k / 30.0 - time.perf_counter()))
            session.wait_idle(600)
        drag_frames = [(tf, f) for tf, f in watch.since(t0) if tf <= moves[-1][0] + 0.05]
        view_frames = [t for t in view.sent if t0 <= t <= moves[-1][0] + 0.05]
        for sent, p in moves:
            for tf, f in watch.since(sent):
                if np.allclose(f[i, :3], p, atol=1e-6):
                    latencies.append(tf - sent)
                    break
        span = (drag_frames[-1][0] - drag_frames[0][0]) if len(drag_frames) > 1 else float("nan")
        lat = np.array(latencies) * 1e3
        return {
            "side": side, "nodes": side * side, "device": session.device, "session_seconds": made,
            "display_nodes": int(topo["n_vertices"]), "topology_ms": topo_s * 1e3, "topology_bytes": topo_bytes,
            "frame_bytes": len(data), "encode_ms": encode_s * 1e3,
            "training_frames_per_s": len(run) / run_s if run_s == run_s and run_s > 0 else None,
            "training_cycles_per_s": cycles / run_s if run_s > 0 else None,
            "drag_frames_per_s": (len(drag_frames) - 1) / span if span == span and span > 0 else None,
            "view_frames_per_s": (len(view_frames) - 1) / (view_frames[-1] - view_frames[0])
            if len(view_frames) > 1 else None,
            "training_cycles": cycles,
            "move_to_frame_median_ms": float(np.median(lat)) if len(lat) else None,
            "move_to_frame_p90_ms": float(np.percentile(lat, 90)) if len(lat) else None,
            "answered_moves": len(lat),
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,  # this process so far
        }
    finally:
        if view is not None:
            view.close()
        session.close()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sides", default="256,1000")
    ap.add_argument("--device", default="cuda:0")
    ap.add_argument("--train-seconds", type=float, default=600.0)
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    out = {"machine": platform.node(), "date": time.strftime("%Y-%m-%d"), "results": []}
    for side in (int(s) for s in args.sides.split(",")):
        r = measure(side, args.device, args.train_seconds)
        out["results"].append(r)
        print(f"{r['nodes']:,} nodes on {r['device']}: display {r['display_nodes']:,} nodes, frame "
              f"{r['frame_bytes'] / 1e6:.2f} MB encoded in {r['encode_ms']:.1f} ms, topology "
              f"{r['topology_bytes'] / 1e6:.2f} MB in {r['topology_ms']:.0f} ms; training "
              f"{r['training_frames_per_s'] or 0:.1f} frames/s ({r['training_cycles']} cycles); drag "
              f"{r['drag_frames_per_s'] or 0:.1f} frames/s (view {r['view_frames_per_s'] or 0:.1f}), "
              f"move -> frame {r['move_to_frame_median_ms'] or 0:.1f} / {r['move_to_frame_p90_ms'] or 0:.1f} ms "
              f"(median / p90, {r['answered_moves']} moves); session made in {r['session_seconds']:.1f} s; peak RSS "
              f"{r['peak_rss_mb']:.0f} MB",
              flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
