"""Profile every Python process started with this folder on PYTHONPATH and SOMWIDGET_PROFILE_DIR set (bench_studio.py
--profile DIR sets both): cProfile, written at exit (or at `dump()`) to DIR/<role>-<pid>.prof; bench_studio.py then
summarises the roles in DIR/profile.txt (profile_summary.py). A benchmark's tool only; nothing in somwidget imports it.

Python 3.11 and older: one profile a thread (threading.setprofile starts each). Python 3.12 and newer: cProfile runs
on sys.monitoring, one tool for the whole process; a second profile cannot start ("Another profiling tool is already
active", raised into the new thread's first call: the studio's own thread died that way and it never started), and the
first one sees every thread already, so threads start none.

SOMWIDGET_PROFILE_CLOCK=cpu (bench_studio.py --profile-clock cpu): each thread's profile counts its own CPU time
(time.thread_time), not wall time: on a machine shared with other work, a thread waiting for a core then counts
nothing, so two runs compare by the work done. Python 3.11 and older only (a profile a thread).
"""

import atexit
import cProfile
import os
import sys
import threading
import time

_DIR = os.environ.get("SOMWIDGET_PROFILE_DIR")
#: The profiles' clock: each thread's CPU time (SOMWIDGET_PROFILE_CLOCK=cpu, a profile a thread) or wall time.
_CPU = os.environ.get("SOMWIDGET_PROFILE_CLOCK") == "cpu" and sys.version_info < (3, 12)
_CLOCK = (time.thread_time,) if _CPU else ()
#: Whether one profile sees every thread (cProfile on sys.monitoring, Python 3.12+).
PROCESS_WIDE = sys.version_info >= (3, 12)
_profiles: list = []
_lock = threading.Lock()
_dumped = False


def _start_thread(*_):
    sys.setprofile(None)
    profile = cProfile.Profile(*_CLOCK)
    try:
        profile.enable()
    except ValueError:  # a profiler of the whole process is on already: it sees this thread
        return
    with _lock:
        _profiles.append(profile)


def role_of() -> str:
    """What this process is, from how it was started: the studio's worker, a Dask worker, the benchmark (the front)."""
    main = sys.modules.get("__main__")
    spec = getattr(main, "__spec__", None)
    name = getattr(spec, "name", "") or ""
    argv = " ".join(sys.argv)
    if name.endswith("studio.worker") or "studio/worker" in argv or "studio.worker" in argv:
        return "worker"
    if "distributed" in name or "dask" in argv:
        return "dask"
    if "bench_studio" in argv:
        return "front"
    return "other"


def dump(role: str | None = None) -> None:
    """Every thread's profile, merged, to the folder (role: what this process is); once a process."""
    global _dumped
    import pstats

    with _lock:
        if _dumped:
            return
        _dumped = True
        profiles = list(_profiles)
    for p in profiles:
        try:
            p.disable()
        except Exception:  # another thread's: disabled by its own stop
            pass
    stats = None
    for p in profiles:
        try:
            stats = pstats.Stats(p) if stats is None else stats.add(p)
        except TypeError:  # a profile with nothing in it
            pass
    if stats is not None:
        stats.dump_stats(os.path.join(_DIR, f"{role or role_of()}-{os.getpid()}.prof"))


if _DIR:
    if not PROCESS_WIDE:
        threading.setprofile(_start_thread)
    _main = cProfile.Profile(*_CLOCK)
    _profiles.append(_main)
    _main.enable()
    atexit.register(dump)
