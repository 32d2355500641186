"""The command line (`somwidget --help`, `serve`, `bench`) and the benchmark's numpy baseline."""

import json
import math
import os
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from somwidget import cli
from somwidget.cli import _build_parser, load_bench_harness, main

ROOT = Path(__file__).resolve().parents[2]
SERVE_OPTIONS = ("--preset", "--mesh", "--host", "--port", "--device", "--open")
BENCH_OPTIONS = ("--device", "--cases", "--cycles", "--repeats", "--json", "--no-baseline")


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return env


def _subparser(name):
    parser = _build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    return sub.choices[name]


def test_console_script_help():
    script = Path(sys.executable).parent / "somwidget"
    if not script.exists():
        if os.environ.get("CI"):
            pytest.fail(f"the console script is missing: {script} (scripts/setup.sh installs it with pip install -e)")
        pytest.skip("somwidget is not installed in this environment (pip install -e .)")
    out = subprocess.run([str(script), "--help"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "serve" in out.stdout and "bench" in out.stdout


def test_module_help_and_no_command():
    out = subprocess.run([sys.executable, "-m", "somwidget.cli", "--help"], capture_output=True, text=True,
                         timeout=120, cwd=ROOT, env=_env())
    assert out.returncode == 0, out.stderr
    assert "serve" in out.stdout and "bench" in out.stdout
    assert main([]) == 2  # no subcommand: prints the help, exits non-zero


@pytest.mark.parametrize("command, options", [("serve", SERVE_OPTIONS), ("bench", BENCH_OPTIONS)])
def test_subcommand_help_lists_every_option(command, options, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main([command, "--help"])
    assert exit_info.value.code == 0
    text = capsys.readouterr().out
    for option in options:
        assert option in text, f"{command} --help does not list {option}"
    for action in _subparser(command)._actions:
        assert action.help, f"{command} option {action.option_strings} has no help text"


def test_serve_defaults_and_passes_options(monkeypatch):
    calls = []
    fake = types.ModuleType("somwidget.frontend.web.serve")
    fake.run_server = lambda **kwargs: calls.append(kwargs)
    monkeypatch.setitem(sys.modules, "somwidget.frontend.web.serve", fake)
    assert main(["serve"]) == 0
    assert calls[-1] == dict(preset=None, mesh=None, host="127.0.0.1", port=8080, device="auto", open_browser=False,
                           lan=False, fresh=False)
    assert main(["serve", "--preset", "car", "--host", "0.0.0.0", "--port", "9001", "--device", "cpu", "--open"]) == 0
    assert calls[-1] == dict(preset="car", mesh=None, host="0.0.0.0", port=9001, device="cpu", open_browser=True,
                           lan=False, fresh=False)
    assert main(["serve", "--fresh"]) == 0 and calls[-1]["fresh"] is True
    assert main(["serve", "--mesh", "bunny.obj"]) == 0
    assert calls[-1]["mesh"] == "bunny.obj" and calls[-1]["preset"] is None


def test_serve_preset_and_mesh_exclude_each_other(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["serve", "--preset", "car", "--mesh", "bunny.obj"])
    assert exit_info.value.code == 2
    assert "not allowed with" in capsys.readouterr().err


def test_bench_refuses_unknown_case(capsys):
    assert main(["bench", "--device", "cpu", "--cases", "teapot"]) == 2
    assert "teapot" in capsys.readouterr().err


def test_bench_says_it_needs_a_checkout(monkeypatch, tmp_path, capsys):
    """An installed somwidget has no benchmarks/ beside it: `somwidget bench` says where it runs, and exits 2."""
    monkeypatch.setattr(cli, "BENCH_HARNESS", tmp_path / "benchmarks" / "engine_harness.py")
    assert main(["bench", "--device", "cpu", "--cases", "car", "--cycles", "5"]) == 2
    err = capsys.readouterr().err
    assert "checkout of the somwidget repository" in err and "engine_harness.py is missing" in err


def test_bench_tiny_run_on_cpu(tmp_path):
    """A real run: the table has ratio columns holding positive finite numbers (no timing thresholds)."""
    report = tmp_path / "bench.json"
    out = subprocess.run(
        [sys.executable, "-m", "somwidget.cli", "bench", "--device", "cpu", "--cases", "car", "--cycles", "20",
         "--repeats", "1", "--json", str(report)],
        capture_output=True, text=True, timeout=600, cwd=ROOT, env=_env())
    assert out.returncode == 0, out.stdout + out.stderr
    rows = [[cell.strip() for cell in line.strip().strip("|").split("|")]
            for line in out.stdout.splitlines() if line.startswith("| ")]
    header, body = rows[0], rows[1:]
    ratio_columns = [i for i, name in enumerate(header) if name.startswith("ratio")]
    assert ratio_columns, f"no ratio column in {header}"
    car = next(row for row in body if row[0] == "car")
    for i in ratio_columns:
        value = float(car[i].replace(",", ""))
        assert math.isfinite(value) and value > 0, f"{header[i]} = {car[i]}"

    shaping = [line for line in out.stdout.splitlines() if "shaping path" in line or "shaping run" in line]
    assert len(shaping) == 3 and "ratio" in shaping[1] and "us a cycle" in shaping[2], out.stdout  # issue 34's two

    data = json.loads(report.read_text())
    handles = data["handles"]
    assert handles["card"] and handles["ratio"] > 0 and handles["run_us_per_cycle"] > 0
    (result,) = data["results"]
    assert result["case"] == "car" and result["neurons"] == 602 and result["controls"] == 18 and result["dims"] == 5
    assert result["cycles"] == 20 and result["device"] == "cpu"
    assert math.isfinite(result["ratio_run"]) and result["ratio_run"] > 0
    # the baselines do the engine's cycles: same winners every cycle (or a near-tie that float32 rounding broke
    # the other way, which the harness measures), and weights equal to float32 rounding until then
    assert result["numpy_update"] in ("fused", "sequential") and set(result["agreement"]) == {"fused", "sequential"}
    for update, agreement in result["agreement"].items():
        if agreement["agree_cycles"] < 20:
            assert agreement["tie_gap"] < 1e-5, (update, agreement)
        assert agreement["max_abs_diff"] < 1e-4, (update, agreement)


# ------------------------------------------------------------------------------------------------------------
# The numpy baseline against a plain float64 reference of the cycle (backend/som.py)
# ------------------------------------------------------------------------------------------------------------
def _reference(weights, controls, distances, table, cycles, metric, smoothing, smooth_dims, offsets, neighbors):
    w = weights.astype(np.float64)
    c = controls.astype(np.float64)
    margins = []
    for s in range(cycles):
        d2 = (((c[:, None, :] - w[None]) ** 2) * metric).sum(axis=2)
        ordered = np.sort(d2, axis=1)
        margins.append((ordered[:, 1] - ordered[:, 0]).min())
        winners = d2.argmin(axis=1)
        for k in range(len(c)):
            for v in range(len(w)):
                d = int(distances[winners[k], v])
                rate = 0.0 if d == 65535 else float(table[s, d])
                w[v] += rate * (c[k] - w[v])
        if smoothing > 0:
            before = w.copy()
            for v in range(len(w)):
                nb = neighbors[offsets[v]:offsets[v + 1]]
                if len(nb):
                    mean = before[nb][:, smooth_dims].mean(axis=0)
                    w[v, smooth_dims] = before[v, smooth_dims] + smoothing * (mean - before[v, smooth_dims])
    return w, min(margins)


@pytest.mark.parametrize("shape", ["grid", "hub"])  # even degrees: padded neighbour table; a hub: CSR segments
@pytest.mark.parametrize("update", ["fused", "sequential"])
def test_numpy_baseline_matches_reference(shape, update):
    from somwidget.backend.topology import Topology

    harness = load_bench_harness()

    rng = np.random.default_rng(7)
    side = 6
    idx = np.arange(side * side).reshape(side, side)
    quads = np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], axis=-1).reshape(-1, 4)
    edges = [(int(a), int(b)) for q in quads for a, b in zip(q, np.roll(q, -1))]
    if shape == "hub":
        edges += [(0, v) for v in range(2, side * side, 2)]
    n = side * side + 1  # the last vertex has no edge: unreachable from the rest, and it never smooths
    topo = Topology.from_edges(np.array(edges), n)
    weights = rng.normal(size=(n, 4)).astype(np.float32)
    weights[-1] = 50.0  # far from every control: never a winner
    controls = rng.normal(scale=2.0, size=(5, 4)).astype(np.float32)
    metric = np.array([1.0, 1.0, 0.5, 2.0], np.float32)
    dims = (0, 1, 3)  # not contiguous
    cycles = 6
    table = harness.schedule_table({"iterations": cycles, "l_start": 0.3, "l_end": 0.03}, topo.d_max).astype(np.float32)
    distances = topo.grid_distances()
    base = harness.NumpySom(distances, topo.offsets, topo.neighbors, weights, controls, table, metric_weights=metric,
                    smoothing=0.3, smooth_dims=dims, update=update)
    assert base._padded == (shape == "grid")
    ref, margin = _reference(weights, controls, distances, table, cycles, metric, 0.3, list(dims), topo.offsets,
                             topo.neighbors)
    assert margin > 1e-4  # winners well separated (float32 rounding is ~1e-6 here): both pick the same ones
    assert base.step(cycles + 5) == cycles  # stops at S
    np.testing.assert_allclose(base.W, ref, rtol=0, atol=2e-5)
    assert base.W[-1].tolist() == pytest.approx(weights[-1].tolist())  # unreachable and alone: never moved
    base.reset()
    np.testing.assert_array_equal(base.W, weights)
