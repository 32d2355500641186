"""Design variants (somwidget.sweep): seeding, each variant equal to its own single run, from a preset and from a
session, parameter ranges, the gallery, a variant back into a session as one undo step, a real 2-worker Dask
LocalCluster giving the same results, and `somwidget sweep` on the command line."""

from __future__ import annotations

import numpy as np
import pytest

import somwidget
from somwidget import Som, Symmetry, presets
from somwidget.backend.variants import plan_variants, run_batch
from somwidget.cli import main as cli_main
from somwidget.frontend.model import Session


def _single_run(preset, controls, params, start=None, restart=False, base=None):
    """A variant's own Som: a whole run, or (`restart`) its controls set on `start` where they were at `base` (each
    moved control with a radius a typed move from there)."""
    som = Som(preset.topology, preset.weights, controls if base is None else base, iterations=params["iterations"],
              l_start=params["l_start"],
              l_end=params["l_end"], smoothing=params["smoothing"], reach=params["reach"],
              smooth_dims=preset.smooth_dims, metric_weights=preset.metric_weights, mirror=preset.mirror, device="cpu",
              radii=preset.control_radii(), symmetry=preset.symmetry, smoothing_rule=preset.smoothing_rule)
    if restart:
        som.restore(start, som.iterations)
        som.set_controls(controls)
    som.train()
    return som.weights


def test_the_same_seed_gives_the_same_variants_and_each_equals_its_single_run():
    params = {"l_start": (0.15, 0.35), "iterations": [150, 200], "smoothing": 0.01}
    a = somwidget.sweep("car", n=6, jitter=0.05, params=params, seed=3, device="cpu", progress=False)
    b = somwidget.sweep("car", n=6, jitter=0.05, params=params, seed=3, device="cpu", progress=False, batch_size=4)
    c = somwidget.sweep("car", n=6, jitter=0.05, params=params, seed=4, device="cpu", progress=False)
    np.testing.assert_array_equal(a.controls, b.controls)
    np.testing.assert_array_equal(a.weights, b.weights)  # batches of 4 + 2 or one batch of 6: the same bits
    assert not np.array_equal(a.controls, c.controls)
    car = presets.get_preset("car")
    assert a.controls.shape == (6, len(car.controls), 5) and a.weights.shape == (6, car.n_vertices, 5)
    # the controls moved by at most the jitter share of the size, in the position dims only
    size = np.linalg.norm(np.ptp(car.weights[:, :3], axis=0))
    moved = np.linalg.norm(a.controls[:, :, :3] - car.controls[None, :, :3], axis=2)
    assert moved.max() <= 0.05 * size + 1e-5 and moved.max() > 0.01 * size
    same = np.broadcast_to(car.controls[:, 3:], a.controls[:, :, 3:].shape)
    np.testing.assert_array_equal(a.controls[:, :, 3:], same)
    for p in a.params:
        assert 0.15 <= p["l_start"] <= 0.35 and p["iterations"] in (150, 200) and p["smoothing"] == 0.01
        assert p["l_end"] == car.l_end and p["reach"] == car.reach
    for i in (0, 5):
        np.testing.assert_array_equal(a.weights[i], _single_run(car, a.controls[i], a.params[i]))
    assert set(a.metrics) == {"gap", "spike", "symmetry", "size"}
    assert all(v.shape == (6,) and np.isfinite(v).all() for v in a.metrics.values())
    assert a.metrics["symmetry"].max() < 1e-5  # mirrored pairs keep the car symmetric


def test_a_sweep_from_a_session_restarts_from_its_shape_and_a_variant_is_one_undo_step():
    with Session("lattice", device="cpu") as session:
        session.move_control(0, session.controls[0, :3] + 0.2)
        session.wait_idle(60)
        shape = session.files.snapshot()["weights"]
        places = session.controls
        v = somwidget.sweep(session, n=3, jitter=0.1, seed=1, device="cpu", progress=False)
        lattice = presets.get_preset("lattice")
        params = v.params[1]
        np.testing.assert_array_equal(v.weights[1], _single_run(lattice, v.controls[1], params, shape, restart=True,
                                                                base=places))
        assert np.abs(v.weights[1] - shape).max() > 0.01  # the typed moves carried the clay
        # the far part of the shape is kept: a local restart, not a regrown lattice
        assert np.median(np.linalg.norm(v.weights[1] - shape, axis=1)) < 0.1 * np.ptp(shape[:, 0])
        before = session.history
        v.apply(1)
        assert session.history == (before[0] + 1, 0)
        np.testing.assert_array_equal(session.frame.weights, v.weights[1])
        np.testing.assert_allclose(session.controls, v.controls[1])
        assert not session.frame.running
        session.undo()
        np.testing.assert_array_equal(session.frame.weights, shape)


def test_plans_with_handles_run_as_single_soms_each_a_typed_move():
    """Controls with radii (handles) under a mirror or a radial group, Taubin's smoothing: single Soms (the batch runs
    the paper's rule only), each variant the typed move of its controls from the design's places (each moved control
    grabbed there and released, the run to S), equal to its own Som; the moved controls took the clay with them."""
    p = presets.get_preset("sphere")
    radii = p.control_radii()[:2]
    base = {"iterations": 60, "l_start": p.l_start, "l_end": p.l_end, "smoothing": 0.1, "reach": p.reach}
    for symmetry, mirror in ((None, (1,)), (Symmetry.radial(4, "z"), ())):
        plan = plan_variants(p.topology, p.weights, p.controls[:2], base, 2, jitter=0.1, seed=1, mirror=mirror,
                             radii=radii, symmetry=symmetry, smoothing_rule="taubin")
        assert plan.singles and plan.handles
        weights, _ = run_batch(plan, "cpu")
        for i in range(2):
            som = Som(p.topology, p.weights, p.controls[:2], **plan.params(i), mirror=mirror, radii=radii,
                      symmetry=symmetry, smoothing_rule="taubin", device="cpu")
            som.restore(p.weights, som.iterations)
            som.set_controls(plan.controls[i])
            som.train()
            np.testing.assert_array_equal(weights[i], som.weights)
            assert np.abs(weights[i] - p.weights).max() > 0.02


def test_the_gallery_shows_each_variant():
    v = somwidget.sweep("sphere", n=4, jitter=0.2, params={"iterations": 100}, device="cpu", progress=False)
    img = v.picture(indices=[0, 1, 2, 3], columns=2, size=(160, 120))
    assert img.shape == (240, 320, 3) and img.dtype == np.uint8
    tiles = [img[r * 120:(r + 1) * 120, c * 160:(c + 1) * 160].astype(int) for r in range(2) for c in range(2)]
    for tile in tiles:  # each thumbnail draws something (not the bare background)
        assert (np.abs(tile - tile[2, -2]).sum(axis=2) > 60).mean() > 0.05
    assert any(np.abs(tiles[0] - t).mean() > 0.5 for t in tiles[1:])  # and they are not all the same picture


@pytest.mark.parametrize("kwargs, message", [
    ({"params": {"speed": (0, 1)}}, "params: unknown parameter(s) ['speed']"),
    ({"params": {"l_start": (0.5, 0.1)}}, "the range's low 0.5 is above its high 0.1"),
    ({"params": {"l_end": (0.0, 0.1)}}, "params['l_end']"),
    ({"params": {"iterations": []}}, "the list of values is empty"),
    ({"n": 0}, "n"),
    ({"jitter": -0.1}, "jitter"),
])
def test_bad_sweeps_are_named(kwargs, message):
    args = {"n": 2, "device": "cpu", "progress": False, **kwargs}
    with pytest.raises(ValueError) as info:
        somwidget.sweep("lattice", **args)
    assert message in str(info.value)


def test_a_two_worker_dask_cluster_gives_the_same_variants():
    distributed = pytest.importorskip("distributed")
    seen = []
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        spread = somwidget.sweep("car", n=8, params={"iterations": 120}, seed=2, device="cpu", client=client,
                                 progress=lambda done, total: seen.append((done, total)))
        workers = {w for w in client.run(lambda: 1)}
    here = somwidget.sweep("car", n=8, params={"iterations": 120}, seed=2, device="cpu", progress=False)
    assert len(workers) == 2
    np.testing.assert_array_equal(spread.weights, here.weights)
    for name in here.metrics:
        np.testing.assert_array_equal(spread.metrics[name], here.metrics[name])
    assert seen == [(i, 8) for i in range(1, 9)]  # four batches a worker (one variant each): a report each


def test_the_command_line_writes_arrays_and_a_gallery(tmp_path, capsys):
    out = tmp_path / "v" / "variants.npz"
    assert cli_main(["sweep", "--preset", "sphere", "--n", "3", "--jitter", "0.1", "--vary", "iterations=60,80",
                     "--vary", "l_start=0.2:0.3", "--out", str(out), "--device", "cpu"]) == 0
    data = np.load(out)
    assert data["weights"].shape == (3, presets.get_preset("sphere").n_vertices, 3)
    assert set(data["param_iterations"].tolist()) <= {60, 80}
    assert ((data["param_l_start"] >= 0.2) & (data["param_l_start"] <= 0.3)).all()
    assert (tmp_path / "v" / "variants.png").stat().st_size > 1000
    assert "closest to its controls: variant" in capsys.readouterr().out
    assert cli_main(["sweep", "--vary", "l_start=fast", "--out", str(out)]) == 2
    assert "--vary 'l_start=fast'" in capsys.readouterr().err
