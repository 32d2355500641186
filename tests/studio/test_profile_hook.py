"""benchmarks/profile_hook and profile_summary.py: a process started under the hook has its threads profiled (a
thread that the hook broke would die before its work: Python 3.12's cProfile refuses a second profiler), and the
summary names each role's own functions."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))
from profile_summary import figures, role_stats, write_summary  # noqa: E402

SCRIPT = """
import threading, time

def busy_in_thread():
    t = time.perf_counter()
    while time.perf_counter() - t < 0.2:
        sum(range(1000))
    print("thread done", flush=True)

def idle_in_thread():
    threading.Event().wait(0.3)

threads = [threading.Thread(target=f) for f in (busy_in_thread, idle_in_thread)]
for t in threads:
    t.start()
for t in threads:
    t.join()
import sitecustomize
sitecustomize.dump("worker")
"""


def test_threads_profiled_and_summarised(tmp_path):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT / "benchmarks" / "profile_hook"), str(ROOT)]),
               SOMWIDGET_PROFILE_DIR=str(tmp_path))
    done = subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert "thread done" in done.stdout, done.stderr  # the thread ran its work under the hook
    profiles = list(tmp_path.glob("worker-*.prof"))
    assert len(profiles) == 1  # dumped once (the exit's dump does not write it again)
    stats, n = role_stats(tmp_path)["worker"]
    names = {func[2] for func in stats.stats}
    assert {"busy_in_thread", "idle_in_thread"} <= names
    f = figures(stats)
    assert f["waiting_s"] >= 0.25  # the idle thread's wait counted as waiting, not work
    assert 0.15 <= f["busy_outside_s"]
    text = write_summary(tmp_path).read_text()
    assert "== worker: 1 process" in text
    own = text.split("most time of their own")[1].split("-- most time inside")[0]
    assert "busy_in_thread" in own and "wait" not in own.split("\n", 1)[1]
