"""Work is never lost (issue 27), each test written as the fault: a real `somwidget serve` stopped by SIGTERM, SIGINT
and SIGKILL (mid-drag too), then started again; two servers and a Python session at once; many stopped sessions;
a directory and a corrupt file where a saved session should be. The servers are driven through the views' websocket
(/view/ws) and read through GET /api/state (positions are the weights' position dims, exactly)."""

from __future__ import annotations

import asyncio
import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
from helpers import ROOT, Serve, wait_for

from somwidget.frontend.model import Session, autosave, recovery, storage
from somwidget.frontend.model import store as _store


# -- driving a server as its views do -----------------------------------------------------------------------------
async def _send(base: str, messages: list, pause: float = 0.05, hold=None) -> None:
    """Send `messages` (intents) on the views' websocket; with `hold`, call `await hold()` before closing it (a
    client that goes away mid-drag ends the drag: a test that kills the server mid-drag keeps it open)."""
    import aiohttp

    async with aiohttp.ClientSession() as cs, cs.ws_connect(base.replace("http", "ws") + "/view/ws") as ws:
        for m in messages:
            await ws.send_json(m)
            await asyncio.sleep(pause)
        await ws.send_json({"type": "ping", "t": 1})  # every intent before it is applied once its pong comes
        while True:
            msg = await ws.receive(timeout=30)
            if msg.type == aiohttp.WSMsgType.TEXT and '"pong"' in msg.data:
                break
            assert msg.type in (aiohttp.WSMsgType.TEXT, aiohttp.WSMsgType.BINARY), msg
            assert '"error"' not in (msg.data if msg.type == aiohttp.WSMsgType.TEXT else ""), msg.data
        if hold is not None:
            await hold()


def send(srv: Serve, messages: list, hold=None) -> None:
    asyncio.run(_send(srv.base, messages, hold=hold))


def drag(index: int, to) -> list:
    """A drag as a view makes it: grab, a few moves, release at `to`."""
    return [{"type": "grab", "index": index}, *({"type": "move", "index": index, "position": list(p)}
            for p in np.linspace(np.asarray(to) - 0.06, to, 4).tolist()),
            {"type": "release", "index": index}]


def settled(srv: Serve) -> dict:
    """The state once training has stopped and every intent is applied, after the autosave has written it: its
    manifest names as many undo and redo steps, no drag is open in it (a release trains nothing, so a save made
    during the drag can hold the same numbers), and its current step holds these controls and positions."""
    st = srv.idle(60)
    folder, session = _folder(srv), st["session"]

    def saved() -> bool:
        manifest = _store.peek(folder)
        if manifest is None or [len(manifest["undo"]), len(manifest["redo"])] != session["history"]:
            return False
        if manifest.get("gesture", False):  # written while a drag was open: its release's save is on its way
            return False
        try:
            with np.load(folder / manifest["current"]["file"]) as z:
                return manifest["current"]["iteration"] == session["frame"]["iteration"] and \
                    np.array_equal(z["controls"], np.float32(session["controls"])) and \
                    np.array_equal(z["weights"][:, :3], np.float32(session["frame"]["positions"]))
        except OSError:  # replaced meanwhile
            return False
    wait_for(saved, 30, "the autosave of the settled state")
    return st


def _folder(srv: Serve):
    from pathlib import Path

    return Path(srv.state()["session"]["autosave"]["path"])


def same(a: dict, b: dict) -> None:
    """Controls, radii, parameters, weights (positions) and s alike, exactly."""
    sa, sb = a["session"], b["session"]
    assert sa["preset"] == sb["preset"]
    np.testing.assert_array_equal(sa["controls"], sb["controls"])
    np.testing.assert_array_equal(sa["radii"], sb["radii"])
    assert sa["parameters"] == sb["parameters"]
    np.testing.assert_array_equal(sa["frame"]["positions"], sb["frame"]["positions"])
    assert sa["frame"]["iteration"] == sb["frame"]["iteration"]


def stop(srv: Serve, sig) -> None:
    srv.proc.send_signal(sig)
    srv.proc.wait(30)
    srv.stop()


def test_sigterm_and_sigint_keep_the_work_and_its_undo(tmp_path):
    env = {"SOMWIDGET_DATA_DIR": str(tmp_path / "data")}
    srv = Serve(env=env)
    try:
        send(srv, drag(2, [3.0, 0.6, 0.2]))
        send(srv, [{"type": "set", "name": "reach", "value": 0.1}])
        before = settled(srv)
        send(srv, drag(4, [-0.2, 0.7, 1.3]))
        after = settled(srv)
        assert after["session"]["history"] == [3, 0]
        stop(srv, signal.SIGTERM)
        srv = Serve(env=env)  # a stop by SIGTERM: the next start brings it back, undo history and all
        back = srv.state(positions=True)
        same(back, after)
        assert back["session"]["history"] == [3, 0] and back["session"]["recovered"]
        message = back["session"]["recovered_message"]
        assert "as its last completed step; Undo reaches the 3 steps before it" in message, message
        assert message in srv.output() and back["panel"]["recovered_message"] == message
        send(srv, [{"type": "undo"}])
        same(srv.idle(), before)  # the step before the last one, exactly
        send(srv, [{"type": "redo"}])
        same(srv.idle(), after)
        send(srv, drag(1, [2.5, -0.5, 0.4]))
        third = settled(srv)
        stop(srv, signal.SIGINT)  # Ctrl+C
        srv = Serve(env=env)
        back = srv.state(positions=True)
        same(back, third)
        assert back["session"]["history"] == [4, 0]
        send(srv, [{"type": "undo"}])
        same(srv.idle(), after)
    finally:
        srv.stop()
    srv = Serve("--fresh", env=env)  # --fresh starts anew, the saved session stays for later
    try:
        st = srv.state()
        assert st["session"]["preset"] == "car" and not st["session"]["recovered"]
        assert st["session"]["history"] == [0, 0] and st["panel"]["recovered_message"] == ""
    finally:
        srv.stop()
    folders = [p for p in (tmp_path / "data" / "autosave").iterdir() if p.is_dir()]
    assert len(folders) == 2, folders


def test_sigkill_mid_drag_brings_back_what_the_message_says(tmp_path):
    """A kill during a drag: the last completed step comes back, or the drag as a step of its own that Undo removes;
    the message says which, and what came back is that. A control pressed but not moved yet is the first (nothing
    changed), a drag moved and held (past its longest wait for a save, so it was written) the second."""
    env = {"SOMWIDGET_DATA_DIR": str(tmp_path / "data")}
    target = [3.2, 0.5, 0.3]
    rounds = {"pressed": ([{"type": "grab", "index": 2}], 0.3),
              "dragged": ([{"type": "grab", "index": 2}, {"type": "move", "index": 2, "position": target}],
                          autosave.AUTOSAVE_SECONDS * (1 + autosave.AUTOSAVE_JITTER) + 1.5)}
    for reach, (name, (intents, hold)) in zip((0.12, 0.13), rounds.items()):
        srv = Serve(env=env)
        try:
            send(srv, [{"type": "set", "name": "reach", "value": reach}])  # a step (the session before it is back)
            srv.wait(lambda s, reach=reach: s["session"]["parameters"]["reach"] == reach, what=f"reach {reach}")
            pre = settled(srv)

            async def kill_while_held(hold=hold, srv=srv):
                await asyncio.sleep(hold)
                os.kill(srv.proc.pid, signal.SIGKILL)  # the drag is still held: its websocket is open
                srv.proc.wait(10)

            send(srv, intents, hold=kill_while_held)
        finally:
            srv.stop()
        srv = Serve(env=env)
        try:
            back = srv.state(positions=True)
            message = back["session"]["recovered_message"]
            if name == "dragged":
                assert "during a drag that was not released" in message and "Undo removes" in message, message
                np.testing.assert_array_equal(back["session"]["controls"][2][:3], np.float32(target))
                assert back["session"]["history"] == [pre["session"]["history"][0] + 1, 0]
                send(srv, [{"type": "undo"}])
                same(srv.idle(), pre)  # Undo removes the drag: the step before it, exactly
            else:
                assert "as its last completed step" in message and "drag" not in message, message
                same(back, pre)
                assert back["session"]["history"] == pre["session"]["history"]
        finally:
            stop(srv, signal.SIGTERM)


# A Python session (a notebook's kernel): three steps, then it waits to be killed.
CHILD = textwrap.dedent("""
    import json, sys, time
    import numpy as np
    from somwidget.frontend.model import Session

    s = Session("grid", device="cpu")
    assert s.wait_idle(60)
    with s.gesture():
        for t in np.linspace(0.1, 1.0, 4):
            s.move_control(1, s.controls[1, :3] + t * np.float32([0.0, 0.05, 0.1]))
    s.settings.set("reach", 0.09)
    assert s.wait_idle(60) and s.autosave.flush()
    print(json.dumps({"controls": s.controls.tolist(), "weights": s.frame.weights.tolist(),
                      "history": list(s.history)}), flush=True)
    time.sleep(600)
""")


def test_two_servers_and_a_python_session_each_keep_their_own(tmp_path, monkeypatch):
    data = tmp_path / "data"
    env = {"SOMWIDGET_DATA_DIR": str(data)}
    monkeypatch.setenv("SOMWIDGET_DATA_DIR", str(data))
    child = subprocess.Popen([sys.executable, "-c", CHILD], env={**os.environ, "PYTHONPATH": str(ROOT), **env},
                             stdout=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        held = json.loads(child.stdout.readline())
    finally:
        child.kill()  # the kernel dies
        child.wait(10)
    a, b = Serve("--preset", "torus", env=env), Serve("--preset", "sphere", env=env)
    try:
        send(a, drag(1, [0.2, 1.4, 0.3]))
        send(b, drag(3, [-0.3, 0.1, 1.5]))
        want = {"torus": settled(a), "sphere": settled(b)}
    finally:
        stop(a, signal.SIGTERM)
        stop(b, signal.SIGINT)
    a, b = Serve(env=env), Serve(env=env)  # two servers again: each brings back one, never the same one
    try:
        got = {s.state()["session"]["preset"]: s.state(positions=True) for s in (a, b)}
        assert sorted(got) == ["sphere", "torus"], sorted(got)
        for name in got:
            same(got[name], want[name])
            assert got[name]["session"]["history"] == [1, 0]
    finally:
        a.stop()
        b.stop()
    s = Session.recover(device="cpu")  # the Python session: left for Session.recover(), never taken by serve
    try:
        assert s is not None and s.preset.name == "grid" and list(s.history) == held["history"]
        np.testing.assert_array_equal(s.controls, np.float32(held["controls"]))
        np.testing.assert_array_equal(s.frame.weights, np.float32(held["weights"]))
        assert s.frame.held and not s.frame.running
    finally:
        s.close()


def test_a_notebook_kernel_that_closes_keeps_its_session(tmp_path, monkeypatch):
    """A real IPython kernel makes a session and a step that nothing has written yet (its training thread not
    started), then is shut down as a notebook closes it (a shutdown request: the kernel exits): the session is written
    on the way out, and Session.recover() brings it back with its step."""
    from jupyter_client.manager import start_new_kernel

    data = tmp_path / "data"
    monkeypatch.setenv("SOMWIDGET_DATA_DIR", str(data))
    km, kc = start_new_kernel(env={**os.environ, "PYTHONPATH": str(ROOT)}, cwd=str(ROOT))
    printed: list[str] = []
    try:
        reply = kc.execute_interactive(textwrap.dedent("""
            import json
            from somwidget.frontend.model import Session
            s = Session("sphere", device="cpu", start=False)
            s.move_control(1, s.controls[1, :3] + 0.1)
            print(json.dumps([(s.autosave.path / "manifest.json").exists(), s.controls.tolist()]))
        """), timeout=120, output_hook=lambda m: printed.append(m["content"].get("text", "")))
        assert reply["content"]["status"] == "ok", reply["content"]
    finally:
        km.shutdown_kernel(now=False)  # what closing the notebook does
        kc.stop_channels()
    saved_before, controls = json.loads("".join(printed))
    assert not saved_before  # nothing on disk until the kernel closed
    s = Session.recover(device="cpu")
    try:
        assert s is not None and s.preset.name == "sphere" and s.history == (1, 0)
        np.testing.assert_array_equal(s.controls, np.float32(controls))
        assert "as its last completed step" in s.recovered["message"]
    finally:
        s.close()


def test_stopped_sessions_are_pruned_by_age_count_and_size(tmp_path, monkeypatch):
    monkeypatch.setenv("SOMWIDGET_DATA_DIR", str(tmp_path))
    s = Session("grid", device="cpu", start=False)
    s.add_control()
    assert s.autosave.flush()
    s.close()
    source = s.autosave.path
    folder = storage.autosave_dir()
    now = time.time()
    ages_days = [0.1 * i for i in range(60)] + [40.0, 45.0]  # 62 stopped sessions; two past KEEP_DAYS
    for i, age in enumerate(ages_days):
        target = folder / f"old-{i:02d}"
        shutil.copytree(source, target)
        t = now - age * 86400 - 120
        os.utime(target / _store.MANIFEST, (t, t))
    served = folder / "served"  # the web app's last session, older than 50 of Python's
    shutil.copytree(source, served)
    manifest = json.loads((served / _store.MANIFEST).read_text())
    (served / _store.MANIFEST).write_text(json.dumps(dict(manifest, origin="serve")))
    t = now - 20 * 86400
    os.utime(served / _store.MANIFEST, (t, t))
    shutil.rmtree(source)
    size = _store._size(folder / "old-00")
    gone = _store.prune()  # the defaults: 30 days, 50 sessions, 4 GiB
    left = sorted(p.name for p in folder.iterdir())
    assert left == [f"old-{i:02d}" for i in range(_store.KEEP_SESSIONS)] + ["served"]
    assert len(gone) == 12
    _store.prune(keep_bytes=3 * size)  # the size bound: as many as fit, newest first
    assert sorted(p.name for p in folder.iterdir()) == ["old-00", "old-01", "old-02", "served"]
    _store.prune(keep_bytes=0)  # the newest stopped session of each origin is always kept
    assert sorted(p.name for p in folder.iterdir()) == ["old-00", "served"]


def _listing(path):
    """What a folder holds (relative paths), or a file's bytes."""
    return sorted(str(p.relative_to(path)) for p in path.rglob("*")) if path.is_dir() else path.read_bytes()


def test_serve_starts_past_unreadable_saved_sessions_and_keeps_them_aside(tmp_path, monkeypatch):
    """A folder where the manifest should be, a manifest cut short, every step file cut short (nothing of the session
    can be read; one step that can be read comes back: test_recovery_partial.py): the server starts anew, says what
    is wrong and where (printed, and in the panel's notices), and each is renamed aside, whole."""
    data = tmp_path / "data"
    monkeypatch.setenv("SOMWIDGET_DATA_DIR", str(data))
    s = Session("torus", device="cpu", start=False, origin="serve")
    s.add_control()
    assert s.autosave.flush()
    s.close()
    good = s.autosave.path
    damaged = {}
    for i, damage in enumerate(["manifest is a folder", "manifest cut short", "step files cut short"]):
        folder = good.with_name(f"damaged-{i}")
        shutil.copytree(good, folder)
        manifest = folder / _store.MANIFEST
        if damage == "manifest is a folder":
            manifest.unlink()
            manifest.mkdir()
            where = manifest
        elif damage == "manifest cut short":
            manifest.write_bytes(manifest.read_bytes()[:40])
            where = manifest
        else:
            records = json.loads(manifest.read_text())
            for record in [records["current"], *records["undo"]]:
                (folder / record["file"]).write_bytes((folder / record["file"]).read_bytes()[:300])
            where = folder / records["current"]["file"]
        damaged[folder] = (str(where), _listing(folder))
    shutil.rmtree(good)
    srv = Serve(env={"SOMWIDGET_DATA_DIR": str(data)})
    try:
        st = srv.state()
        assert st["session"]["preset"] == "car" and not st["session"]["recovered"]  # started anew
        notices = st["session"]["notices"]
        assert len(notices) == 3, notices
        for folder, (where, listing) in damaged.items():
            said = [n for n in notices if where in n]
            assert len(said) == 1 and "kept at" in said[0], (where, notices)
            assert where in srv.output()
            aside, = [p for p in data.joinpath("autosave").iterdir() if p.name.startswith(folder.name + ".unreadable")]
            assert _listing(aside) == listing  # nothing in it deleted
        send(srv, drag(2, [3.0, 0.6, 0.2]))  # and the new session saves as any other
        settled(srv)
    finally:
        srv.stop()


def test_serve_starts_when_a_file_is_where_the_autosave_folder_should_be(tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    (data / "autosave").write_bytes(b"not a folder")
    srv = Serve(env={"SOMWIDGET_DATA_DIR": str(data)})
    try:
        st = srv.state()
        notices = " ".join(st["session"]["notices"])
        assert f"the autosave folder {data / 'autosave'} was a file" in notices and "kept at" in notices, notices
        aside, = [p for p in data.iterdir() if p.name.startswith("autosave.unreadable")]
        assert aside.read_bytes() == b"not a folder"
        send(srv, drag(2, [3.0, 0.6, 0.2]))
        settled(srv)
    finally:
        srv.stop()


def test_an_earlier_versions_autosave_is_brought_back_once(tmp_path, monkeypatch):
    """An autosave left by somwidget before the session folders (`autosave/<id>.npz`, a session file, beside its free
    `<id>.lock`, as a killed process left it) is brought back by the next `somwidget serve` exactly as saved, with a
    message that says so; the file is renamed, kept, and not taken again. One whose lock is held (a live process of
    that version) is left alone."""
    from somwidget.frontend.model.store import lock

    data = tmp_path / "data"
    monkeypatch.setenv("SOMWIDGET_DATA_DIR", str(data))
    folder = data / "autosave"
    folder.mkdir(parents=True)
    s = Session("sphere", device="cpu", autosave=False)
    s.move_control(2, [0.2, -1.3, 0.4])
    assert s.wait_idle(60)
    s.save(folder / "20261120-101500-4242-0abc1234.npz")
    (folder / "20261120-101500-4242-0abc1234.lock").touch()
    saved_controls, saved_weights, saved_s = s.controls, s.frame.weights.copy(), s.frame.iteration
    s.close()
    live = folder / "20261120-090000-4141-0def5678.npz"  # older, and its process still holds its lock
    shutil.copy(folder / "20261120-101500-4242-0abc1234.npz", live)
    held = lock(live.with_suffix(".lock"))
    os.utime(live, (time.time() - 3600, time.time() - 3600))
    srv = Serve(env={"SOMWIDGET_DATA_DIR": str(data)})
    try:
        st = srv.state(positions=True)
        session = st["session"]
        assert session["preset"] == "sphere" and "earlier version" in session["recovered_message"], session
        np.testing.assert_array_equal(session["controls"], saved_controls)
        np.testing.assert_array_equal(session["frame"]["positions"], saved_weights[:, :3])
        assert session["frame"]["iteration"] == saved_s
        kept = [p.name for p in folder.iterdir() if ".brought-back-" in p.name]
        assert len(kept) == 1 and kept[0].startswith("20261120-101500-4242-0abc1234.npz"), kept
        assert live.exists()  # a live session's file is not taken
    finally:
        srv.stop()
    assert recovery.legacy_stopped() == []  # the live one's lock is still held; the other was renamed
    held.close()
    assert recovery.legacy_stopped() == [live]  # its process gone, it would be next
