"""A studio's worker: rooms in a process of their own (one a GPU on a multi-GPU host), served to the front by a room
server (host.py) on loopback.

    SOMWIDGET_STUDIO_SECRET=... python -m somwidget.frontend.studio.worker --rooms DIR --device cuda:0 --label "GPU 0"

prints `somwidget studio worker at http://127.0.0.1:PORT` once it listens, and serves until its front closes its
stdin or it is sent SIGTERM (every room saved). `LocalWorkers` (workers.py) starts them. Imports no UI package: numpy,
warp and aiohttp are all it needs.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading

from .limits import StudioLimits
from .rooms import FRAME_RATE, Rooms

ANNOUNCE = "somwidget studio worker at "
SECRET_ENV = "SOMWIDGET_STUDIO_SECRET"
#: Seconds between the main thread's looks for a stop (SIGTERM, SIGINT, the front gone).
SIGNAL_POLL = 0.2


def main(argv=None) -> int:
    from .host import RoomServer

    parser = argparse.ArgumentParser(prog="python -m somwidget.frontend.studio.worker")
    parser.add_argument("--rooms", required=True, help="the studio's rooms folder")
    parser.add_argument("--device", default="auto")
    parser.add_argument("--label", default=None)
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=0)
    parser.add_argument("--rooms-per-worker", type=int, default=StudioLimits.rooms)
    parser.add_argument("--nodes-per-room", type=int, default=StudioLimits.nodes)
    parser.add_argument("--memory-per-worker", type=float, default=None)
    parser.add_argument("--park-after", type=float, default=StudioLimits.park_after)
    parser.add_argument("--frame-rate", type=float, default=FRAME_RATE)
    args = parser.parse_args(argv)
    secret = os.environ.get(SECRET_ENV, "")
    if not secret:
        print(f"{parser.prog}: error: set {SECRET_ENV} (the front's secret for its workers)", file=sys.stderr)
        return 2
    limits = StudioLimits(args.rooms_per_worker, args.nodes_per_room, args.memory_per_worker, args.park_after)
    rooms = Rooms(args.rooms, device=args.device, limits=limits, frame_rate=args.frame_rate,
                  label=args.label or f"worker {os.getpid()} ({args.device})")
    rooms.warm()
    server = RoomServer(rooms, secret, host=args.host, port=args.port).start()
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    print(ANNOUNCE + server.url, flush=True)

    def watch_stdin():  # the front went (its pipe closed): stop too
        try:
            sys.stdin.read()
        except (OSError, ValueError):
            pass
        stop.set()

    threading.Thread(target=watch_stdin, daemon=True).start()
    # in short waits: a signal that another thread of the process took runs its handler only when this (the main)
    # thread next runs Python, and a wait without end would outlast the front's patience (then it kills the worker)
    while not stop.wait(SIGNAL_POLL):
        pass
    server.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
