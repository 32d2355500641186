"""The modelling session (somwidget.frontend.model.session): intents in, frames out, one training thread.

These tests drive the Session through its Python API, as a view would (the protocol, not the interaction:
tests/test_app_browser.py drags with a real mouse). They run the real Som on the CPU.
"""

from __future__ import annotations

import sys
import threading
import time

import numpy as np
import pytest

from somwidget.backend import presets
from somwidget.backend.presets import parse_hex_colour, rgb_to_colour_dims
from somwidget.backend.schedule import MAX_ITERATIONS
from somwidget.backend.som import Som
from somwidget.backend.topology import Topology
from somwidget.frontend.model import Frame, Session
from somwidget.frontend.model import session as session_module
from somwidget.frontend.model.settings import MAX_TABLE_ENTRIES


@pytest.fixture
def session():
    s = Session("car", device="cpu")
    yield s
    s.close()


def _nearest(positions: np.ndarray, p) -> float:
    return float(np.sqrt(((positions - np.asarray(p, np.float32)) ** 2).sum(axis=1)).min())


def _until(condition, timeout: float = 60.0, what: str = "condition") -> None:
    """Poll `condition()` until it holds; fail after a generous `timeout` (a loaded machine is slow, not wrong)."""
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"{what}: not reached within {timeout:g} s"
        time.sleep(0.01)


def test_session_does_not_import_ui_packages():
    code = ("import sys, somwidget.frontend.model.session as s; "
            "bad = [m for m in ('trame', 'pyvista', 'vtk', 'vtkmodules', 'ipywidgets') if m in sys.modules]; "
            "print(bad); raise SystemExit(1 if bad else 0)")
    import subprocess

    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr


def test_trains_to_S_in_frames_and_stops(session):
    frames: list[Frame] = []
    session.add_listener(frames.append)
    assert session.wait_idle(30)
    last = session.frame
    assert last.iteration == last.iterations == 1000
    assert not last.running
    # several frames on the way, numbered in order, each a consistent picture
    seqs = [f.seq for f in frames]
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
    assert len(frames) >= 3
    f = frames[-1]
    n = session.preset.n_vertices
    assert f.weights.shape == (n, 5) and f.positions.shape == (n, 3) and f.colours.shape == (n, 3)
    assert f.controls.shape == (9, 5) and f.effective_controls.shape == (18, 5)
    assert f.control_colours.shape == (9, 3) and f.effective_colours.shape == (18, 3)
    assert f.gaps.shape == (18,) and f.cycle_time > 0
    assert not f.weights.flags.writeable  # shared by every listener: read-only
    np.testing.assert_allclose(f.positions, f.weights[:, :3])
    # mirrored copies: y negated
    np.testing.assert_allclose(f.effective_controls[9:, 1], -f.effective_controls[:9, 1])
    # gaps: distance to the nearest node, by brute force
    for j in (0, 11):
        assert f.gaps[j] == pytest.approx(_nearest(f.positions, f.effective_positions[j]), rel=1e-5, abs=1e-6)
    # once converged, no more frames arrive
    count = len(frames)
    time.sleep(0.3)
    assert len(frames) == count


def test_step_size_targets_the_frame_rate():
    """k (cycles per step) grows until a step fills its share of a frame interval: step_fraction / frame_rate
    seconds at the measured cycle time. Checked on what the frames report, not on a frame rate, which a busy
    machine cannot promise."""
    s = Session("car", device="cpu", paused=True)
    try:
        frames: list[Frame] = []
        s.set_iterations(200_000)
        s.add_listener(frames.append, replay=False)
        s.train()
        budget = s.trainer.step_fraction / s.trainer.frame_rate

        def steps():
            return [f for f in list(frames) if f.step_cycles > 0]

        # frames keep coming while training, and the step grows to fill the budget (the first steps are 1 cycle)
        _until(lambda: len(steps()) >= 20, what="20 training frames")
        _until(lambda: any(f.step_cycles * f.cycle_time >= budget / 3 for f in steps()),
               what=f"a step of at least a third of the {budget * 1e3:.0f} ms budget")
        assert max(f.step_cycles for f in steps()) > 1
        s.pause()
        assert s.wait_idle(30)
        assert 0 < s.frame.iteration < 200_000
    finally:
        s.close()


def test_move_control_restarts_schedule_and_mesh_follows(session):
    assert session.wait_idle(30)
    before = session.frame
    target = np.array([3.2, 1.4, 0.9], np.float32)
    d_before = _nearest(before.positions, target)
    session.move_control(2, target)
    # the session's own copy changes at once; the other features stay
    np.testing.assert_allclose(session.controls[2, :3], target)
    np.testing.assert_allclose(session.controls[2, 3:], before.controls[2, 3:])
    assert session.wait_idle(30)
    after = session.frame
    assert after.iteration == after.iterations
    np.testing.assert_allclose(after.controls[2, :3], target)
    np.testing.assert_allclose(after.effective_controls[9 + 2, :3], target * [1, -1, 1])
    d_after = _nearest(after.positions, target)
    assert d_after < 0.5 * d_before
    # the schedule restarts locally from the latest weights, not from the start mesh: s0 = floor((1 - reach) S) for a
    # short move (a long one widens the reach: tests/model/test_long_moves.py)
    session.pause()
    session.move_control(2, [3.2, 1.4, 0.95])
    assert session.wait_applied(10)
    paused = session.frame
    assert paused.iteration == 920 and session.parameters["reach"] == 0.08
    np.testing.assert_array_equal(paused.weights, after.weights)


def test_moves_within_a_frame_collapse_and_all_land(session):
    session.pause()
    for x in np.linspace(1.0, 3.0, 50):
        session.move_control(0, [x, 0.9, -0.7])
    assert session.wait_applied(10)
    np.testing.assert_allclose(session.frame.controls[0, :3], [3.0, 0.9, -0.7], rtol=1e-6)


@pytest.mark.parametrize("bad", [
    (99, [0, 0, 0]), (-1, [0, 0, 0]), (1.5, [0, 0, 0]), (True, [0, 0, 0]), (0, [np.nan, 0, 0]),
    (0, [0, np.inf, 0]), (0, [0, 0]), (0, [0, 0, 0, 0]), (0, "abc"), (0, [[0, 0, 0]]), (0, [1e9, 0, 0]),
])
def test_bad_move_is_refused_and_changes_nothing(session, bad):
    assert session.wait_idle(30)
    seq, controls = session.frame.seq, session.controls
    with pytest.raises(ValueError, match=r"control"):
        session.move_control(*bad)
    np.testing.assert_array_equal(session.controls, controls)
    time.sleep(0.1)
    assert session.frame.seq == seq  # nothing queued, no frame


def test_parameters_are_validated_and_reach_the_som(session):
    session.set_iterations(500)
    session.settings.update(l_start=0.4, l_end=0.05)
    session.set_smoothing(0.2)
    session.set_parameter("S", "600")  # a text field's value
    assert session.wait_idle(30)
    p = session.parameters
    assert (p["iterations"], p["l_start"], p["l_end"], p["smoothing"]) == (600, 0.4, 0.05, 0.2)
    som = session.modelling.som
    assert (som.iterations, som.l_start, som.l_end, som.smoothing) == (600, 0.4, 0.05, 0.2)
    assert session.frame.iteration == 600
    for name, value in [("iterations", 0), ("iterations", -3), ("iterations", 2.5), ("iterations", "ten"),
                        ("iterations", float("nan")), ("iterations", True), ("iterations", 10**9),
                        ("l_start", 0.0), ("l_start", 1.5), ("l_end", float("nan")), ("l_end", "inf"),
                        ("smoothing", -0.1), ("smoothing", 2), ("metric_weights", [1, 1, 1]),
                        ("metric_weights", [0, 0, 0, 0, 0]), ("metric_weights", [1, 1, -1, 1, 1]),
                        ("metric_weights", [1, 1, np.nan, 1, 1]), ("symmetry", "maybe"), ("nonsense", 1)]:
        with pytest.raises(ValueError):
            session.set_parameter(name, value)
    assert session.parameters == p
    session.settings.set_metric_weights([1, 1, 1, 0.5, 0])
    assert session.wait_idle(30)
    np.testing.assert_allclose(session.modelling.som.metric_weights, [1, 1, 1, 0.5, 0])


def test_symmetry_off_and_on_moves_nothing(session):
    """Off, the mirrored copies become controls of their own (18 controls, the same 18 pulls) and no node moves; on
    again, they pair up as before (9 controls and their copies), and still no node moves."""
    assert session.wait_idle(30)
    before = session.frame.weights.copy()
    session.settings.set_symmetry(False)
    assert session.wait_applied(30) and session.wait_idle(30)
    assert session.n_controls == 18 and session.frame.effective_controls.shape == (18, 5)
    assert session.parameters["symmetry"] is False and session.parameters["group"] == "none"
    np.testing.assert_array_equal(session.frame.weights, before)
    session.settings.set_symmetry(True)
    assert session.wait_applied(30) and session.wait_idle(30)
    assert session.n_controls == 9 and session.frame.effective_controls.shape == (18, 5)
    assert session.parameters["group"] == "mirror-y"
    np.testing.assert_array_equal(session.frame.weights, before)
    assert session.undo() and session.n_controls == 18  # each change one step
    session.settings.set_symmetry("radial-3-z")  # a group whose copies are not there yet: they appear, the clay follows
    assert session.wait_applied(30) and session.wait_idle(30)
    assert session.n_controls == 18 and session.frame.effective_controls.shape == (54, 5)


def test_set_symmetry_none_turns_it_off_and_a_group_never_merges_controls_silently():
    """`Session.set_symmetry(None)` is off (it was refused: "expected true or false"). On the torus, whose six
    controls hold two mirror pairs, a mirror keeps all six with a copy each and says which are images; off, then the
    same group on again: the copies pair up with their controls as before, and says so."""
    s = Session("torus", device="cpu", autosave=False)
    try:
        said = s.set_symmetry("mirror-y")
        assert s.n_controls == 6 and s.wait_applied(30) and len(s.frame.effective_controls) == 12
        assert "6 controls kept" in said and "2 and 3" in said and "4 and 5" in said
        assert s.settings.notice == said and s.settings.notices == 1
        said = s.set_symmetry(None)
        assert s.parameters["symmetry"] is False and s.parameters["group"] == "none" and s.n_controls == 12
        assert said.startswith("symmetry off: 12 controls")
        said = s.set_symmetry("mirror-y")
        assert s.n_controls == 6 and "12 controls paired up again as 6" in said
        steps = s.history[0]
        s.set_symmetry(None)
        assert s.undo() and s.parameters["group"] == "mirror-y" and s.history[0] == steps
    finally:
        s.close()


def test_reset_restores_the_start_mesh(session):
    assert session.wait_idle(30)
    start = session.preset.weights
    assert np.abs(session.frame.weights - start).max() > 0.1
    session.pause()
    session.reset()
    assert session.wait_idle(30)
    np.testing.assert_array_equal(session.frame.weights, start)
    assert session.frame.iteration == 0 and not session.frame.running
    session.train()
    assert session.wait_idle(30)
    assert session.frame.iteration == 1000


def test_pause_and_train(session):
    session.set_iterations(100_000)
    _until(lambda: session.frame.iteration > 0, what="training after set_iterations")
    session.pause()
    assert session.wait_idle(30)
    s = session.frame.iteration
    assert session.frame.paused and not session.frame.running
    time.sleep(0.3)  # paused: nothing may move however long we wait
    assert session.frame.iteration == s and session.frame.paused and not session.frame.running
    session.train()
    _until(lambda: session.frame.iteration > s, what="training after train()")
    assert session.frame.running
    session.pause()


def test_add_remove_control_and_colour(session):
    i = session.add_control()
    assert i == 9 and session.n_controls == 10
    session.set_control_colour(i, "#00ff00")
    assert session.wait_idle(30)
    f = session.frame
    assert f.controls.shape == (10, 5) and f.effective_controls.shape == (20, 5)
    np.testing.assert_allclose(f.control_colours[i], [0, 1, 0], atol=1e-6)
    session.remove_control(0)
    assert session.wait_idle(30)
    assert session.frame.controls.shape == (9, 5)
    for bad in ["#12345", "red", "#gg0000", None]:
        with pytest.raises(ValueError):
            session.set_control_colour(0, bad)
    with pytest.raises(ValueError):
        session.set_control_colour(0, [1.5, 0, 0])
    with pytest.raises(ValueError):
        session.remove_control(9)
    for _ in range(8):
        session.remove_control(0)
    with pytest.raises(ValueError, match="last control"):
        session.remove_control(0)
    assert session.n_controls == 1


def test_colour_helpers_live_in_presets_only():
    for name in ("rgb_to_colour_dims", "parse_hex_colour", "hex_colour"):  # one home: no re-export by the session
        assert callable(getattr(presets, name))
    assert not hasattr(session_module, "hex_colour")
    assert presets.hex_colour([1.0, 128 / 255, 0.0]) == "#ff8000"
    assert not hasattr(Session, "set_control")  # replaced by move_control / set_control_feature / set_controls


def test_colour_conversion_inverts_colours_of():
    layout = presets.car().layout
    for rgb in ([1, 0, 0], [0.2, 0.4, 1.0], [1, 1, 1]):
        dims = rgb_to_colour_dims(rgb, layout)
        row = np.zeros(5, np.float32)
        row[list(layout.colour)] = dims
        np.testing.assert_allclose(presets.colours_of(row, layout)[0], rgb, atol=1e-5)
    np.testing.assert_allclose(parse_hex_colour("#ff8000"), [1, 128 / 255, 0], atol=1e-6)
    with pytest.raises(ValueError, match="no colour"):
        rgb_to_colour_dims([1, 0, 0], presets.XYZ)


def test_listeners(session):
    got_a, got_b = [], []

    def broken(frame):
        raise RuntimeError("a broken view")

    session.add_listener(broken)
    session.add_listener(got_a.append)
    session.add_listener(got_b.append)
    session.move_control(0, [1.0, 1.0, -1.0])
    assert session.wait_idle(30)
    assert got_a and [f.seq for f in got_a] == [f.seq for f in got_b]
    session.remove_listener(got_a.append)
    n = len(got_a)
    session.move_control(0, [1.2, 1.0, -1.0])
    assert session.wait_idle(30)
    assert len(got_a) == n and len(got_b) > n
    with pytest.raises(ValueError):
        session.add_listener("not callable")


def test_intents_from_many_threads_leave_a_consistent_session(session):
    errors = []

    def tab(seed):
        rng = np.random.default_rng(seed)
        try:
            for _ in range(60):
                r = rng.random()
                if r < 0.6:
                    session.move_control(int(rng.integers(0, 9)), rng.normal(size=3))
                elif r < 0.7:
                    session.set_iterations(int(rng.integers(50, 400)))
                elif r < 0.8:
                    session.settings.set("l_start", float(rng.uniform(0.1, 0.9)))
                elif r < 0.85:
                    session.reset()
                else:
                    try:
                        session.move_control(0, [np.nan, 0, 0])
                    except ValueError:
                        pass
                time.sleep(0.002)
        except Exception as exc:  # pragma: no cover - reported below
            errors.append(exc)

    threads = [threading.Thread(target=tab, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    assert session.wait_idle(60)
    f = session.frame
    np.testing.assert_array_equal(f.controls, session.controls)  # the Som got the last word of every tab
    assert np.isfinite(f.weights).all() and f.iteration == f.iterations == session.parameters["iterations"]
    assert session.error is None


def test_load_preset_and_bad_inputs(session, tmp_path):
    gen = session.generation
    with pytest.raises(ValueError, match="unknown preset"):
        session.load_preset("nope")
    assert session.preset.name == "car" and session.generation == gen
    session.load_preset("lines")
    assert session.wait_idle(30)
    f = session.frame
    assert f.generation == gen + 1 and f.weights.shape == (602, 8) and f.effective_controls.shape == (16, 8)
    assert session.preset.display == "lines"
    bad = tmp_path / "bad.obj"
    bad.write_text("this is not a mesh\n")
    with pytest.raises(ValueError):
        session.load_mesh(bad)
    flat = tmp_path / "flat.obj"
    flat.write_text("v 0 0 0\nv 0 0 0\nv 0 0 0\nf 1 2 3\n")
    with pytest.raises(ValueError, match="degenerate"):
        session.load_mesh(flat)
    assert session.preset.name == "lines" and session.generation == gen + 1
    small = Session("sphere", device="cpu", max_vertices=500, start=False)
    try:
        with pytest.raises(ValueError, match="at most 500"):
            small.load_preset("torus")
    finally:
        small.close()
    good = tmp_path / "tetra.obj"
    good.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n")
    session.load_mesh(good)
    assert session.wait_idle(30)
    assert session.frame.positions.shape == (4, 3) and session.preset.n_vertices == 4


def test_save_load_and_export(session, tmp_path):
    session.set_iterations(300)
    session.move_control(1, [-1.8, 1.2, -0.4])
    assert session.wait_idle(30)
    weights = session.frame.weights.copy()
    path = tmp_path / "s.npz"
    session.save(path)
    for fmt in ("obj", "ply", "glb"):
        out = tmp_path / f"m.{fmt}"
        session.export_mesh(out)
        assert out.stat().st_size > 1000
    session.load_preset("sphere")
    assert session.wait_idle(30)
    session.pause()
    session.load(path)
    assert session.wait_idle(30)
    f = session.frame
    np.testing.assert_allclose(f.weights, weights, atol=1e-6)  # paused: the saved weights, untouched
    np.testing.assert_allclose(f.controls[1, :3], [-1.8, 1.2, -0.4])
    assert session.parameters["iterations"] == 300 and session.preset.display == "surface"
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"PK\x03\x04 not really a zip")
    with pytest.raises(ValueError):
        session.load(junk)
    np.testing.assert_allclose(session.frame.weights, weights, atol=1e-6)


def test_state_is_json_friendly(session):
    import json

    assert session.wait_idle(30)
    st = session.state(positions=True)
    text = json.dumps(st)
    assert '"preset": "car"' in text
    assert len(st["frame"]["positions"]) == 602 and len(st["frame"]["gaps"]) == 18


def test_closed_session_refuses_intents():
    s = Session("sphere", device="cpu")
    s.close()
    with pytest.raises(RuntimeError):
        s.move_control(0, [0, 0, 0])


# -- wait_applied, refused intents and a training thread that fails ------------------------------------------------
def test_wait_applied_returns_only_once_the_frame_has_the_move(session):
    """While training, every move followed by wait_applied finds the move in session.frame: the step that was
    running when the move arrived does not count."""
    session.set_iterations(MAX_ITERATIONS)  # trains all through the test
    assert session.wait_applied(30)
    missing = []
    for i in range(300):
        p = np.float32([1.0 + 0.01 * i, 0.6, -0.4])
        session.move_control(0, p)
        assert session.wait_applied(30), f"move {i} not applied"
        f = session.frame
        if not np.allclose(f.controls[0, :3], p):
            missing.append(i)
    assert not missing, f"{len(missing)} of 300 frames after wait_applied lacked the move: {missing[:10]}"
    assert session.frame.running and session.error is None


def test_wait_applied_counts_intents_handled_by_the_training_thread(session):
    assert session.wait_idle(30)
    applied = session.frame.applied
    session.set_smoothing(0.1)
    session.settings.update(l_start=0.3, l_end=0.05)  # two intents
    assert session.wait_applied(30)
    assert session.frame.applied == applied + 3
    som = session.modelling.som
    assert (som.smoothing, som.l_start, som.l_end) == (0.1, 0.3, 0.05)
    never_started = Session("sphere", device="cpu", start=False)
    try:
        never_started.set_smoothing(0.2)
        t = time.monotonic()
        assert not never_started.wait_applied(30)  # nothing will apply it: say so at once
        assert time.monotonic() - t < 5
    finally:
        never_started.close()


def _chain(n: int) -> presets.Preset:
    """A path of n nodes: d_max = n - 1, so the learning table caps S well below MAX_ITERATIONS."""
    edges = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
    pts = np.zeros((n, 3), np.float32)
    pts[:, 0] = np.linspace(-1.0, 1.0, n)
    return presets.Preset(name="chain", title="Chain", description="a path", topology=Topology.from_edges(edges, n),
                          weights=pts, controls=np.float32([[0.0, 0.5, 0.0]]), layout=presets.XYZ, display="points")


def test_set_iterations_refuses_an_S_the_engine_would_refuse():
    s = Session(_chain(1200), device="cpu", paused=True)
    try:
        limit = MAX_TABLE_ENTRIES // 1200  # d_max + 1 = 1200
        assert limit < MAX_ITERATIONS
        before = s.parameters
        with pytest.raises(ValueError, match=rf"{limit + 1}.*at most {limit}"):
            s.set_iterations(limit + 1)
        with pytest.raises(ValueError, match=rf"{limit + 1}.*at most {limit}"):
            s.set_parameter("S", str(limit + 1))
        assert s.parameters == before and s.error is None
        assert s.settings.max_iterations == limit
        assert s.wait_idle(30)
        assert s.modelling.som.iterations == before["iterations"]
        with s.modelling.som_lock:  # the engine draws the line at the same place
            with pytest.raises(ValueError, match="learning table"):
                s.modelling.som.iterations = limit + 1
        s.set_iterations(5000)
        assert s.wait_applied(30)
        assert s.modelling.som.iterations == s.parameters["iterations"] == 5000 and s.error is None
    finally:
        s.close()
    car = Session("car", device="cpu", start=False)
    try:
        assert car.settings.max_iterations == MAX_ITERATIONS  # d_max is small: the session's own cap holds
    finally:
        car.close()


def test_a_refused_intent_is_rolled_back_and_the_rest_of_its_batch_still_lands(monkeypatch):
    s = Session("car", device="cpu", paused=True)
    try:
        assert s.wait_idle(30)
        before = s.parameters
        smoothing = Som.smoothing

        def refuse(som, value):
            if value == 0.3:
                raise ValueError("no smoothing today")
            smoothing.fset(som, value)

        monkeypatch.setattr(Som, "smoothing", property(smoothing.fget, refuse))
        target = np.float32([2.5, 0.7, 0.3])
        # hold the training thread off: the three intents of one gesture (one undo step) reach it as one batch
        with s.modelling.som_lock, s.gesture():
            s.set_smoothing(0.3)
            s.move_control(2, target)
            s.settings.set("l_start", 0.45)
            assert s.parameters["smoothing"] == 0.3  # the session's view changes at once...
        assert s.wait_applied(30)
        assert "smoothing" in s.error and "no smoothing today" in s.error
        assert s.parameters["smoothing"] == before["smoothing"] == s.modelling.som.smoothing  # ...and back when refused
        # the intents after the refused one reached the Som and the frame
        np.testing.assert_allclose(s.modelling.som.controls[2, :3], target)
        np.testing.assert_allclose(s.frame.controls[2, :3], target)
        np.testing.assert_array_equal(s.frame.controls, s.controls)
        assert s.modelling.som.l_start == s.parameters["l_start"] == 0.45
        # a refused intent followed by a later one of the same kind: the later value stands
        with s.modelling.som_lock:
            s.set_smoothing(0.3)
            s.set_smoothing(0.25)
        assert s.wait_applied(30)
        assert s.parameters["smoothing"] == s.modelling.som.smoothing == 0.25
        monkeypatch.undo()
        s.set_smoothing(0.2)
        s.train()
        assert s.wait_idle(30)
        assert s.error is None and s.modelling.som.smoothing == s.parameters["smoothing"] == 0.2
        assert s.frame.iteration == s.frame.iterations
    finally:
        s.close()


def test_a_failed_step_whose_error_frame_also_fails_keeps_the_thread_alive(monkeypatch):
    s = Session("car", device="cpu", paused=True)
    try:
        assert s.wait_idle(30)
        seq = s.frame.seq

        def broken_step(som, n=1):
            raise RuntimeError("step exploded")

        def broken_frame(cycles):
            raise RuntimeError("frame exploded")

        monkeypatch.setattr(Som, "step", broken_step)
        monkeypatch.setattr(s.trainer, "make_frame", broken_frame)
        s.train()
        t = time.monotonic()
        assert s.wait_idle(30)
        assert time.monotonic() - t < 10  # not a timeout: the thread is alive and paused
        assert s.trainer.thread.is_alive()
        assert "step exploded" in s.error and s.paused
        assert s.frame.seq > seq and s.frame.paused and not s.frame.running
        s.move_control(0, [1.0, 0.5, 0.2])  # intents still get handled (and shown in a frame)
        assert s.wait_applied(30)
        monkeypatch.undo()
        s.train()
        assert s.wait_idle(30)
        assert s.error is None and s.frame.iteration == s.frame.iterations
        np.testing.assert_allclose(s.frame.controls[0, :3], [1.0, 0.5, 0.2])
    finally:
        s.close()


def test_a_dead_training_thread_shows_in_error_and_waits_return_at_once():
    s = Session("car", device="cpu", paused=True)
    try:
        assert s.wait_idle(30)
        should_step = s.trainer.should_step

        def bug():
            if threading.current_thread() is s.trainer.thread:
                raise RuntimeError("a bug in the loop")
            return should_step()

        s.trainer.should_step = bug
        s.train()
        s.trainer.thread.join(30)
        assert not s.trainer.thread.is_alive()
        assert "training thread stopped" in s.error and "a bug in the loop" in s.error
        t = time.monotonic()
        assert not s.wait_idle(30)  # nothing pending, yet not idle: nothing will train any more
        s.train()  # clears the last intent's error, not this one
        assert "training thread stopped" in s.error
        s.move_control(0, [1.0, 0.5, 0.2])
        assert not s.wait_applied(30)
        assert not s.wait_idle(30)
        assert time.monotonic() - t < 5
    finally:
        s.close()


def test_a_65536_vertex_upload_trains_on_the_cpu(tmp_path):
    """Issue 28: a CPU session takes meshes up to 262,144 vertices. A 256 x 256 wave (65,536 vertices) uploads, trains
    on distance rows, and a drag of one control given a small radius carries the clay around it to the control,
    while the far side stays exactly where it was (the local cycle touches only what the drag reaches)."""
    import trimesh

    from somwidget.frontend.model.state import DEFAULT_MAX_VERTICES

    faces, pts = presets.open_grid(256, 256)
    pts[:, 2] = 0.2 * np.sin(3 * pts[:, 0]) * np.cos(2 * pts[:, 1])
    path = tmp_path / "wave.ply"
    trimesh.Trimesh(pts, np.concatenate([faces[:, [0, 1, 2]], faces[:, [0, 2, 3]]]), process=False).export(path)
    s = Session("car", device="cpu", autosave=False, start=False)
    try:
        assert s.max_vertices == DEFAULT_MAX_VERTICES == 262_144
        s.load_mesh(str(path))
        s.start()
        assert s.preset.n_vertices == 65_536 and s.modelling.som.distances == "rows"
        assert s.wait_idle(60)
        before = s.frame.positions.copy()
        s.set_control_radius(0, 0.1)
        start = np.array(s.controls[0][:3], np.float64)
        target = start + [0.0, 0.0, 0.2]
        with s.gesture():
            for k in range(1, 5):
                s.move_control(0, (start + [0.0, 0.0, 0.05 * k]).tolist())
        assert s.wait_idle(120)
        after = s.frame.positions
        assert _nearest(after, target) < 0.01  # the clay reached the control
        far = np.linalg.norm(before - start.astype(np.float32), axis=1) > 1.0
        assert far.sum() > 10_000 and (after[far] == before[far]).all()
    finally:
        s.close()


def test_a_control_keeps_its_id_and_colour_while_others_come_and_go():
    """The views number and colour a control by its stable id (issue 34: Delete renumbered and recoloured every
    control): removing one leaves the others' ids and palette colours; its Undo brings it back with its own; Refine
    keeps every id; another preset's controls are numbered from 0."""
    s = Session("sphere", device="cpu", autosave=False)
    try:
        assert s.wait_idle(120)
        f0 = s.frame
        ids0, colours0 = f0.control_ids, f0.control_display_colours
        assert ids0 == (0, 1, 2, 3, 4, 5) and len({tuple(c) for c in colours0}) == 6
        s.remove_control(2)
        assert s.wait_applied(30)
        f = s.frame
        assert f.control_ids == (0, 1, 3, 4, 5)
        np.testing.assert_array_equal(f.control_display_colours, colours0[[0, 1, 3, 4, 5]])
        s.add_control([0.0, 0.0, 1.0])
        assert s.wait_applied(30)
        assert s.frame.control_ids == (0, 1, 3, 4, 5, 6)  # a new id, never one of the others'
        assert s.undo() and s.undo()
        f = s.frame
        assert f.control_ids == ids0
        np.testing.assert_array_equal(f.control_display_colours, colours0)
        s.remove_control(0)
        assert s.wait_applied(30)
        s.refine()
        assert s.wait_applied(60)
        assert s.frame.n_controls == 5 and s.frame.control_ids == (1, 2, 3, 4, 5)
        np.testing.assert_array_equal(s.frame.control_display_colours, colours0[1:])
        s.load_preset("torus")
        assert s.wait_applied(60)
        assert s.frame.control_ids == tuple(range(s.frame.n_controls))
    finally:
        s.close()


def test_a_typed_radius_after_a_move_makes_the_move_again_with_the_handle():
    """A control with a radius moved by a typed position, then given a larger radius: the move is made again from
    the shape before it (a handle binds at the old place), so the bump widens and still reaches the control (the
    shape before the move alone would leave the clay round, 0.3 short of it)."""
    s = Session("sphere", device="cpu", autosave=False)
    try:
        assert s.wait_idle(120)
        start = s.frame.positions.copy()
        c0 = s.controls[0][:3].copy()
        assert s.control_edits.radii[0] > 0
        s.move_control(0, 1.3 * c0)
        assert s.wait_idle(120)
        pulled = s.frame.positions.copy()
        s.set_control_radius(0, 1.5)
        assert s.wait_idle(120)
        wider = s.frame.positions.copy()
        moved = lambda w: int((np.linalg.norm(w - start, axis=1) > 0.01).sum())  # noqa: E731
        assert moved(wider) > moved(pulled) + 30, (moved(pulled), moved(wider))
        assert _nearest(wider, 1.3 * c0) < 0.01 * np.linalg.norm(start.max(0) - start.min(0))
        np.testing.assert_allclose(s.controls[0][:3], 1.3 * c0, rtol=1e-6)
    finally:
        s.close()


def test_a_group_change_counts_a_stroke_as_one_control_as_the_table_does():
    """The notice after a group change counts controls as the table's rows: a stroke of 30 samples is one (it said
    "38 controls kept" beside a table of 8 rows)."""
    s = Session("grid", device="cpu", autosave=False)
    try:
        assert s.wait_idle(120)
        s.add_stroke([[x, 0.5, 0.0] for x in np.linspace(-0.6, 0.6, 30)])
        assert s.wait_applied(30) and s.n_controls > 6 + 1  # the stroke: its samples (resampled) act as one
        said = s.set_symmetry("mirror-x")
        assert "7 controls kept" in said, said
        said = s.set_symmetry(None)
        assert said.startswith("symmetry off: 14 controls"), said
    finally:
        s.close()
