"""Command line: ``somwidget serve`` (the web app), ``somwidget sweep`` (design variants) and ``somwidget bench``
(engine benchmarks, from a checkout of the repository: their harness is benchmarks/engine_harness.py, no part of the
package).

Heavy imports (warp, trame, pyvista) happen inside the subcommands, so ``somwidget --help`` is fast.
"""

from __future__ import annotations

import argparse
import importlib.util
import re
import sys
from pathlib import Path
from types import ModuleType

from .backend.schedule import KEYS

#: The engine benchmark's harness in a checkout: benchmarks/ beside the somwidget package.
BENCH_HARNESS = Path(__file__).resolve().parent.parent / "benchmarks" / "engine_harness.py"


def device_name(text: str) -> str:
    """--device: auto, cpu, cuda or cuda:N."""
    if text in ("auto", "cpu", "cuda") or re.fullmatch(r"cuda:\d+", text):
        return text
    raise argparse.ArgumentTypeError(f"expected auto, cpu, cuda or cuda:N, got {text!r}")


def _build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="somwidget",
        description="A self-organizing map as computational clay for 3D modelling "
        "(after Felbrich et al., IEEE AIVR 2018).",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    serve = sub.add_parser(
        "serve",
        help="start the web app (trame): drag the controls, watch the mesh follow",
        description="Start the somwidget web app and serve it over HTTP.",
    )
    start = serve.add_mutually_exclusive_group()
    start.add_argument(
        "--preset",
        metavar="NAME",
        help="start from a built-in preset, e.g. car, space-grid, lines (the app's default when neither "
        "--preset nor --mesh is given)",
    )
    start.add_argument(
        "--mesh",
        metavar="FILE",
        help="start from a mesh file (OBJ, PLY, STL, OFF, GLB): its vertices become the neurons, its edges "
        "the synapses",
    )
    serve.add_argument("--host", default=None, help="address to listen on (default: 127.0.0.1, or this machine's "
                       "LAN address with --lan); any address beyond loopback is served over HTTPS with an access token")
    serve.add_argument("--port", type=int, default=8080, help="port to listen on (default: %(default)s)")
    serve.add_argument(
        "--device",
        type=device_name,
        metavar="{auto,cpu,cuda,cuda:N}",
        default="auto",
        help="where the map trains: auto = the GPU when there is one, else the CPU (default: %(default)s)",
    )
    serve.add_argument("--open", action="store_true", help="open the app in the default web browser once it is up")
    serve.add_argument("--lan", action="store_true", help="serve on the LAN for an AR headset: HTTPS with a "
                       "self-signed certificate, an access token in the URL, and a QR code to open it")
    serve.add_argument("--fresh", action="store_true", help="start from --preset / --mesh (by default the app brings "
                       "back the session the last serve left, however it stopped, with its undo history; that "
                       "session stays saved for later)")
    studio = serve.add_argument_group("studio", "many rooms, each a session of its own, and the wall of them all "
                                      "(docs/studio.md)")
    studio.add_argument("--studio", action="store_true", help="serve rooms: /r/<name> opens or makes one, /wall shows "
                        "them all (the teacher's link); --preset is what a new room starts from")
    studio.add_argument("--rooms", metavar="NAMES", default="", help="rooms to have at start, comma-separated (their "
                        "links are printed)")
    studio.add_argument("--rooms-dir", metavar="DIR", help="where the rooms are kept (default: the data directory's "
                        "studio/); with --scheduler, a folder every worker reaches")
    studio.add_argument("--workers", type=int, metavar="N", help="worker processes on this machine, rooms placed on "
                        "the least loaded (default: one a GPU where there are two or more, else the rooms live in "
                        "the server's process)")
    studio.add_argument("--scheduler", metavar="ADDRESS", help="a Dask scheduler (tcp://host:8786) whose workers hold "
                        "the rooms (pip install somwidget[dask])")
    studio.add_argument("--rooms-per-worker", type=int, default=64, metavar="N", help="live rooms a worker (a GPU) "
                        "holds; past it a new room is refused (default: %(default)s)")
    studio.add_argument("--nodes-per-room", type=int, default=65536, metavar="N", help="a room's largest mesh "
                        "(default: %(default)s)")
    studio.add_argument("--memory-per-worker", type=float, metavar="MB", help="memory a worker's rooms may use; past "
                        "it a new room is refused (default: the machine's and the GPU's own)")
    studio.add_argument("--park-after", type=float, default=300.0, metavar="SECONDS", help="a room with no view is "
                        "saved and its memory freed after this long (0: never; default: %(default)s)")

    bench = sub.add_parser(
        "bench",
        help="time the engine against a numpy baseline on the paper's case studies",
        description="Time the Warp engine (a whole run, and step(10) frames as the app calls it) against a "
        "vectorised numpy float32 baseline doing the same cycles, and print a table. Runs from a checkout of the "
        "repository (benchmarks/engine_harness.py).",
    )
    bench.add_argument(
        "--device",
        type=device_name,
        metavar="{auto,cpu,cuda,cuda:N}",
        default="auto",
        help="device for the engine: auto = the GPU when there is one, else the CPU (default: %(default)s)",
    )
    bench.add_argument(
        "--cases",
        metavar="LIST",
        help="comma-separated cases from: space-grid, space-grid-smooth, car, big (default: all four on a GPU; "
        "on the CPU all but big, whose 65,536-neuron dense distance table takes 8 GiB)",
    )
    bench.add_argument(
        "--cycles",
        type=int,
        metavar="S",
        help="cycles per run, the schedule length S (default: 1000, the paper's; the CPU default run takes "
        "about 10 s on two cores)",
    )
    bench.add_argument(
        "--repeats",
        type=int,
        default=3,
        metavar="R",
        help="timed repetitions of each measurement; the median is reported (default: %(default)s)",
    )
    bench.add_argument("--json", metavar="FILE", help="also write the results as JSON to FILE")
    bench.add_argument("--cpu-cores", type=int, metavar="N", help="on the CPU, split each cycle over N cores "
                       "(default: the engine chooses: one for small meshes)")
    bench.add_argument("--no-baseline", action="store_true",
                       help="skip the numpy baseline (the ratio columns then read n/a)")

    sweep = sub.add_parser(
        "sweep",
        help="train many design variants at once and write their arrays and a gallery",
        description="Draw N variants of a design (its controls moved by up to JITTER of its size, schedule "
        "parameters varied with --vary), train them batched on the GPU (or the CPU, or a Dask cluster), and write "
        "their arrays (.npz) and a gallery picture of the first 16 (.png beside it).",
    )
    what = sweep.add_mutually_exclusive_group()
    what.add_argument("--preset", metavar="NAME", default=None, help="a built-in preset (default: car)")
    what.add_argument("--mesh", metavar="FILE", help="a mesh file (OBJ, PLY, STL, OFF, GLB, glTF) with six controls")
    sweep.add_argument("--n", type=int, default=64, help="how many variants (default: %(default)s)")
    sweep.add_argument("--jitter", type=float, default=0.05,
                       help="each control moves by up to this share of the model's size (default: %(default)s)")
    sweep.add_argument("--vary", action="append", default=[], metavar="NAME=LOW:HIGH|NAME=A,B,...",
                       help=f"vary a schedule parameter ({', '.join(KEYS)}) over a range or a list; may be given "
                       "several times")
    sweep.add_argument("--seed", type=int, default=0, help="the same seed gives the same variants (default: 0)")
    sweep.add_argument("--out", default="variants.npz", metavar="FILE.npz",
                       help="where the arrays go (default: %(default)s); the gallery goes beside it as .png")
    sweep.add_argument("--device", type=device_name, metavar="{auto,cpu,cuda,cuda:N}", default="auto",
                       help="where to train here (default: %(default)s); with --scheduler, on the workers")
    sweep.add_argument("--scheduler", metavar="ADDRESS",
                       help="a Dask scheduler (tcp://host:8786) whose workers train the batches (pip install "
                       "somwidget[dask])")
    sweep.add_argument("--no-gallery", action="store_true", help="write the arrays only")
    return parser


def parse_vary(items: list[str]) -> dict:
    """--vary NAME=LOW:HIGH (a range) or NAME=A,B,... (a list) or NAME=VALUE -> sweep's params."""
    out: dict[str, tuple[float, float] | list[float] | float] = {}
    for item in items:
        name, sep, text = item.partition("=")
        name = name.strip()
        if not sep or not text.strip():
            raise ValueError(f"--vary {item!r}: expected NAME=LOW:HIGH or NAME=A,B,...")
        try:
            if ":" in text:
                low, high = text.split(":", 1)
                out[name] = (float(low), float(high))
            elif "," in text:
                out[name] = [float(x) for x in text.split(",") if x.strip()]
            else:
                out[name] = float(text)
        except ValueError:
            raise ValueError(f"--vary {item!r}: {text!r} is not a number, a LOW:HIGH range or a list") from None
    return out


def _sweep(args: argparse.Namespace) -> int:
    import os

    import numpy as np

    from somwidget.backend import io as sw_io
    from somwidget.frontend.model.variants import sweep

    params = parse_vary(args.vary)
    if not args.out.endswith(".npz"):
        raise ValueError(f"--out {args.out!r}: expected a file name ending in .npz")
    design = sw_io.load_mesh(args.mesh) if args.mesh else (args.preset or "car")
    client = None
    if args.scheduler:
        try:
            from distributed import Client
        except ImportError:
            raise ValueError("--scheduler needs Dask: pip install somwidget[dask]") from None
        client = Client(args.scheduler, timeout="30s")
    device = None if args.device == "auto" else args.device
    try:
        variants = sweep(design, n=args.n, jitter=args.jitter, params=params, seed=args.seed, device=device,
                         client=client)
    finally:
        if client is not None:
            client.close()
    arrays = {"controls": variants.controls, "weights": variants.weights,
              **{f"param_{key}": variants.plan.schedules[key] for key in variants.plan.schedules},
              **{f"metric_{key}": value for key, value in variants.metrics.items()},
              "edges": variants.plan.edges, "seed": np.int64(args.seed), "jitter": np.float64(args.jitter)}
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    np.savez_compressed(args.out, **arrays)
    print(f"wrote {args.out}: {len(variants)} variants of {variants.preset.title}")
    if not args.no_gallery:
        png = args.out[:-4] + ".png"
        variants.picture(png)
        print(f"wrote {png}: the first {min(16, len(variants))}")
    best = variants.best("gap")
    print(f"closest to its controls: variant {best} (gap {variants.metrics['gap'][best]:.4f} of its size)")
    return 0


def _studio(args: argparse.Namespace) -> int:
    from somwidget.frontend.studio.limits import StudioLimits
    from somwidget.frontend.studio.serve import run_studio

    if args.mesh or args.fresh:
        raise ValueError("--studio: rooms start from a preset (--preset); --mesh and --fresh are for one session")
    limits = StudioLimits(args.rooms_per_worker, args.nodes_per_room, args.memory_per_worker, args.park_after)
    run_studio(host=args.host if args.host is not None else (None if args.lan else "127.0.0.1"), port=args.port,
               device=args.device, lan_mode=args.lan, workers=args.workers, limits=limits,
               preset=args.preset or "car", rooms_dir=args.rooms_dir,
               rooms=[n for n in args.rooms.split(",") if n.strip()], scheduler=args.scheduler)
    return 0


def _serve(args: argparse.Namespace) -> int:
    if args.studio:
        return _studio(args)
    if args.rooms or args.rooms_dir or args.workers is not None or args.scheduler:
        raise ValueError("--rooms, --rooms-dir, --workers and --scheduler are the studio's: add --studio")
    from somwidget.frontend.web.serve import run_server

    run_server(
        preset=args.preset,
        mesh=args.mesh,
        host=args.host if args.host is not None else (None if args.lan else "127.0.0.1"),
        port=args.port,
        device=args.device,
        open_browser=args.open,
        lan=args.lan,
        fresh=args.fresh,
    )
    return 0


def load_bench_harness() -> ModuleType:
    """benchmarks/engine_harness.py of the checkout this somwidget runs from (`BENCH_HARNESS`); FileNotFoundError
    saying so where there is none (an installed package carries no benchmarks)."""
    if not BENCH_HARNESS.is_file():
        raise FileNotFoundError(
            f"bench: the engine benchmark runs from a checkout of the somwidget repository, and this somwidget has "
            f"none beside it ({BENCH_HARNESS} is missing); clone the repository and run `somwidget bench` or "
            f"`python benchmarks/bench_engine.py` in it")
    name = "somwidget_engine_harness"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, BENCH_HARNESS)
        if spec is None or spec.loader is None:  # a .py file always has both
            raise ImportError(f"bench: {BENCH_HARNESS} cannot be imported as a module")
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module  # (its dataclasses look their module up)
        try:
            spec.loader.exec_module(module)
        except BaseException:
            del sys.modules[name]
            raise
    return sys.modules[name]


def _bench(args: argparse.Namespace) -> int:
    benchmark = load_bench_harness()
    cases = None
    if args.cases:
        cases = [c.strip() for c in args.cases.split(",") if c.strip()]
    results = benchmark.run(
        device=args.device,
        cases=cases,
        cycles=args.cycles,
        repeats=args.repeats,
        baseline=not args.no_baseline,
        json_path=args.json,
        cpu_cores=args.cpu_cores,
    )
    return 0 if results else 1


def main(argv: list[str] | None = None) -> int:
    parser = _build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    try:
        if args.command == "serve":
            return _serve(args)
        if args.command == "bench":
            return _bench(args)
        if args.command == "sweep":
            return _sweep(args)
    except (ValueError, FileNotFoundError) as exc:
        print(f"somwidget: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    parser.error(f"unknown command {args.command!r}")
    return 2


if __name__ == "__main__":
    sys.exit(main())
