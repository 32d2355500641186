"""What a user's install costs: `pip install somwidget` (the wheel built from this checkout, its dependencies from the
package index) in a fresh venv, its size on disk, the largest packages, and the time to the first picture
(`somwidget.render`) in a fresh process with Warp's kernel cache empty (cold) and again (warm). Also what leaving
VTK out would save: the size of pyvista, vtk and every package only they bring in.

    python benchmarks/bench_install.py [--keep DIR]

Needs the browser client built (scripts/setup.sh), the `build` package and the package index reachable. Prints a
Markdown block for BENCHMARKS.md ("Install").
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The packages that draw the still pictures on the server (`render`, the gallery, a notebook run with no browser).
VTK_PACKAGES = ("pyvista", "vtk")

PICTURE = ("import time; t = time.perf_counter(); import somwidget; "
           "s = somwidget.Session('car', device='cpu', autosave=False); assert s.wait_idle(1200); "
           "trained = time.perf_counter() - t; img = somwidget.render(s, 'car.png'); s.close(); "
           "print('picture', img.shape, 'trained after', round(trained, 1), 's')")


def run(cmd, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, check=True, capture_output=True, text=True, **kw)


def du_mib(path: Path) -> float:
    return int(run(["du", "-sk", str(path)]).stdout.split()[0]) / 1024


def sizes(py: Path) -> dict[str, tuple[float, list[str]]]:
    """{distribution: (MiB on disk from its RECORD, its requirements' names)} of a venv."""
    code = r"""
import json, os, re
from importlib import metadata
out = {}
for d in metadata.distributions():
    total = 0
    for f in d.files or ():
        try:
            total += os.path.getsize(d.locate_file(f))
        except OSError:
            pass
    reqs = [re.split(r"[ ;<>=!~\[(]", r, 1)[0].lower().replace("_", "-") for r in (d.requires or ())
            if "extra ==" not in r]
    out[d.metadata["Name"].lower().replace("_", "-")] = (total / 2**20, reqs)
print(json.dumps(out))
"""
    import json

    return json.loads(run([str(py), "-c", code]).stdout)


def closure(names, graph) -> set[str]:
    seen, todo = set(), list(names)
    while todo:
        n = todo.pop()
        if n in seen or n not in graph:
            continue
        seen.add(n)
        todo.extend(graph[n][1])
    return seen


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--keep", help="build in this folder and keep it (default: a temporary one, removed)")
    args = ap.parse_args()
    tmp = Path(args.keep or tempfile.mkdtemp(prefix="somwidget-install-"))
    tmp.mkdir(parents=True, exist_ok=True)
    run([sys.executable, "-m", "build", "--wheel", "--outdir", str(tmp / "dist"), str(ROOT)], timeout=900)
    wheel = max((tmp / "dist").glob("somwidget-*.whl"), key=os.path.getmtime)
    venv = tmp / "venv"
    run([sys.executable, "-m", "venv", str(venv)], timeout=300)
    py = venv / "bin" / "python"
    run([str(py), "-m", "pip", "install", "-q", "--upgrade", "pip"], timeout=600)
    empty = du_mib(venv)
    env = {**os.environ, "PIP_NO_CACHE_DIR": "1"}
    t = time.perf_counter()
    run([str(py), "-m", "pip", "install", "-q", str(wheel)], env=env, timeout=3600)
    install_s = time.perf_counter() - t
    total = du_mib(venv)

    graph = sizes(py)
    own = graph["somwidget"][1]
    everything = closure(own, graph)
    without = closure([n for n in own if n not in VTK_PACKAGES], graph)
    vtk_only = sorted(everything - without)
    vtk_mib = sum(graph[n][0] for n in vtk_only)

    run_env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VTK_DEFAULT_OPENGL_WINDOW")}
    run_env["SOMWIDGET_DATA_DIR"] = str(tmp / "data")
    times = []
    with tempfile.TemporaryDirectory() as warp_cache:
        run_env["WARP_CACHE_PATH"] = warp_cache
        for label in ("cold", "warm"):
            t = time.perf_counter()
            out = run([str(py), "-c", PICTURE], cwd=tmp, env=run_env, timeout=1800).stdout
            times.append((label, time.perf_counter() - t, out.strip().splitlines()[-1]))

    top = sorted(((n, graph[n][0]) for n in everything | {"somwidget"}), key=lambda x: -x[1])[:12]
    cpu = re.sub(r"\s+", " ", next((line.split(":", 1)[1] for line in open("/proc/cpuinfo")
                                    if line.startswith("model name")), platform.processor())).strip()
    print(f"- command: `python benchmarks/bench_install.py` ({datetime.date.today()}, {os.cpu_count()} cores, {cpu}, "
          f"Python {platform.python_version()}, {platform.system()} {platform.machine()})")
    print(f"- `pip install {wheel.name}` into a fresh venv (pip's cache off): {install_s:.0f} s; the venv "
          f"{total:.0f} MiB ({total - empty:.0f} MiB more than an empty venv with pip), {len(everything) + 1} "
          "distributions")
    print("- largest (MiB): " + ", ".join(f"{n} {s:.0f}" for n, s in top))
    print(f"- VTK's share: pyvista, vtk and what only they bring in ({', '.join(vtk_only)}): {vtk_mib:.0f} MiB, "
          f"{100 * vtk_mib / (total - empty):.0f}% of the install")
    for label, seconds, line in times:
        print(f"- first picture, {label} (a fresh process: import, the car's session trained on the CPU, rendered "
              f"off screen by pyvista): {seconds:.1f} s wall ({line})")


if __name__ == "__main__":
    main()
