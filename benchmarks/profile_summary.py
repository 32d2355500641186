"""The profiles benchmarks/profile_hook wrote (DIR/<role>-<pid>.prof) summarised by role in one text file:

    python benchmarks/profile_summary.py DIR          # writes DIR/profile.txt (bench_studio.py --profile does it)

For each role (front, worker, designers, ...; the processes of a role merged): the profiled seconds, the seconds
spent waiting (a lock, an event, a selector, a sleep: idle, not CPU), the seconds inside Warp's launches (on the CPU
device the kernels themselves; on a GPU the launches' host cost) and inside Warp's waits for the device, the busy
seconds outside them, and the functions with the most time of their own and the most time inside them, waits left
out. cProfile times are wall times of the profiled threads, so a busy second here is CPU only where the thread
was not descheduled.
"""

from __future__ import annotations

import argparse
import pstats
import re
import sys
from pathlib import Path

#: Functions whose own time is waiting, not work (cProfile names builtins "<method 'acquire' ...>" and the like).
WAITS = re.compile(r"acquire|\bwait\b|\bsleep\b|select|\bpoll\b|epoll|<method 'control'|readline|recv_into|"
                   r"<built-in method _thread|\bjoin\b|_recv_bytes|waitpid|of '_queue|"
                   r"<method 'read' of '_io\.(FileIO|TextIOWrapper)'")
#: Warp's launches (their cumulative time: the kernels on the CPU device).
LAUNCHES = {"launch", "capture_launch", "launch_tiled"}
#: Warp's waits for the device (a GPU's kernels land here, not in the launches).
DEVICE_WAITS = {"synchronize", "synchronize_device", "synchronize_stream", "numpy"}


#: A worker's round, part by part (ms a frame in the summary): (what, file's tail, function).
ROUND_PARTS = (("the stepping loop's rounds", "studio/rounds.py", "_round"),
               ("  stepping alone (own path)", "model/trainer.py", "step_alone"),
               ("  stepping batched (one launch a batch)", "studio/batched.py", "step"),
               ("    the batches' launches", "backend/batch.py", "_launch"),
               ("  a room's quick calls (the moves)", "model/trainer.py", "run_calls"),
               ("  making frames", "model/frames.py", "make"),
               ("    the nodes' colours", "model/frames.py", "_node_colours"),
               ("  publishing frames", "model/frames.py", "publish"),
               ("  the autosave's turn", "model/trainer.py", "after_turn"),
               ("encoding frames (the views' loop)", "transport/frames.py", "encode_frame"),
               ("Som.set_controls", "backend/som.py", "set_controls"))


def _cumulative(stats: pstats.Stats, tail: str, name: str) -> tuple[int, float]:
    """(calls, seconds inside) of the functions `name` in files ending `tail`."""
    calls, inside = 0, 0.0
    for (path, _line, fname), (_cc, nc, _tt, ct, _c) in stats.stats.items():
        if fname == name and path.replace("\\", "/").endswith(tail):
            calls += nc
            inside += ct
    return calls, inside


def per_frame(stats: pstats.Stats) -> str:
    """A worker's round part by part in ms a frame (frames: FrameStream.make's calls), Warp's launches taken out of
    the rounds' time; empty where this role made no frames."""
    frames, _ = _cumulative(stats, "model/frames.py", "make")
    if not frames:
        return ""
    launches = _cumulative(stats, "backend/batch.py", "_launch")[1] + _cumulative(stats, "model/trainer.py",
                                                                                   "step_alone")[1]
    _, rounds = _cumulative(stats, "studio/rounds.py", "_round")
    lines = [f"-- a frame, part by part ({frames} frames; ms a frame, profiled: slower than unprofiled, compare "
             f"runs with each other): the rounds {1e3 * rounds / frames:.3f}, of which the steps "
             f"{1e3 * launches / frames:.3f}"
             f" (the batches' launches and the rooms stepped alone: on the CPU the kernels), the rest "
             f"{1e3 * (rounds - launches) / frames:.3f}"]
    for what, tail, name in ROUND_PARTS:
        calls, inside = _cumulative(stats, tail, name)
        if calls:
            lines.append(f"{1e3 * inside / frames:>10.3f} ms a frame  {what} ({calls} calls)")
    return "\n".join(lines)


def _label(func: tuple) -> str:
    path, line, name = func
    if path == "~":
        return name
    parts = Path(path).parts
    for anchor in ("somwidget", "warp", "aiohttp", "asyncio", "benchmarks"):
        if anchor in parts:
            path = "/".join(parts[parts.index(anchor):])
            break
    else:
        path = Path(path).name
    return f"{path}:{line}({name})"


def _is_wait(func: tuple) -> bool:
    return bool(WAITS.search(func[2]))


def _in_warp(func: tuple) -> bool:
    return "warp" in Path(func[0]).parts


def role_stats(folder: Path) -> dict[str, tuple[pstats.Stats, int]]:
    """{role: (its processes' profiles merged, how many)} from folder/<role>-<pid>.prof."""
    out: dict[str, tuple[pstats.Stats, int]] = {}
    for path in sorted(folder.glob("*-*.prof")):
        role = path.stem.rsplit("-", 1)[0]
        try:
            stats = pstats.Stats(str(path))
        except (TypeError, EOFError, ValueError, OSError):  # empty or cut short
            continue
        if role in out:
            merged, n = out[role]
            merged.add(stats)
            out[role] = (merged, n + 1)
        else:
            out[role] = (stats, 1)
    return out


def figures(stats: pstats.Stats) -> dict[str, float]:
    """Seconds: profiled, waiting, inside Warp's launches, inside Warp's waits for the device, busy outside both."""
    total = waits = launches = device = 0.0
    for func, (_cc, _nc, tt, ct, _callers) in stats.stats.items():
        total += tt
        if _is_wait(func):
            waits += tt
        if _in_warp(func) and func[2] in LAUNCHES:
            launches += ct
        if _in_warp(func) and func[2] in DEVICE_WAITS:
            device += ct
    return {"profiled_s": total, "waiting_s": waits, "launch_s": launches, "device_wait_s": device,
            "busy_outside_s": max(0.0, total - waits - launches - device)}


def summarise_role(role: str, stats: pstats.Stats, processes: int, top: int = 25) -> str:
    f = figures(stats)
    lines = [f"== {role}: {processes} process{'es' if processes != 1 else ''}; profiled {f['profiled_s']:.2f} s, "
             f"waiting {f['waiting_s']:.2f} s, inside Warp's launches {f['launch_s']:.2f} s, waiting for the device "
             f"{f['device_wait_s']:.2f} s, busy outside them {f['busy_outside_s']:.2f} s"]
    parts = per_frame(stats)
    if parts:
        lines.append(parts)
    rows = [(func, v) for func, v in stats.stats.items() if not _is_wait(func)]
    lines.append("-- most time of their own (waits left out): calls, own s, inside s")
    for func, (_cc, nc, tt, ct, _c) in sorted(rows, key=lambda r: -r[1][2])[:top]:
        lines.append(f"{nc:>10} {tt:>9.3f} {ct:>9.3f}  {_label(func)}")
    lines.append("-- most time inside (waits left out): calls, own s, inside s")
    for func, (_cc, nc, tt, ct, _c) in sorted(rows, key=lambda r: -r[1][3])[:top]:
        lines.append(f"{nc:>10} {tt:>9.3f} {ct:>9.3f}  {_label(func)}")
    return "\n".join(lines)


def write_summary(folder, top: int = 25) -> Path:
    """folder/profile.txt: every role's summary (see the module's docstring); its path."""
    folder = Path(folder)
    roles = role_stats(folder)
    order = sorted(roles, key=lambda r: ({"front": 0, "worker": 1, "designers": 2}.get(r, 3), r))
    text = "\n\n".join(summarise_role(r, *roles[r], top=top) for r in order) if roles else "no profiles found"
    out = folder / "profile.txt"
    out.write_text(f"# profiles under {folder}, by role (benchmarks/profile_summary.py)\n\n{text}\n")
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder")
    parser.add_argument("--top", type=int, default=25)
    args = parser.parse_args(argv)
    print(write_summary(args.folder, args.top))
    return 0


if __name__ == "__main__":
    sys.exit(main())
