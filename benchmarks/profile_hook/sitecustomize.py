"""Profile every thread of every Python process started with this folder on PYTHONPATH and SOMWIDGET_PROFILE_DIR set
(bench_studio.py --profile DIR): one cProfile a thread, written at exit (or at `dump()`) to DIR/<role>-<pid>.prof.
A benchmark's tool only; nothing in somwidget imports it."""

import atexit
import cProfile
import os
import sys
import threading

_DIR = os.environ.get("SOMWIDGET_PROFILE_DIR")
_profiles: list = []
_lock = threading.Lock()


def _start_thread(*_):
    sys.setprofile(None)
    profile = cProfile.Profile()
    with _lock:
        _profiles.append(profile)
    profile.enable()


def dump(role: str | None = None) -> None:
    """Every thread's profile, merged, to the folder (role: what this process is)."""
    import pstats

    with _lock:
        profiles = list(_profiles)
    if not profiles:
        return
    for p in profiles:
        try:
            p.disable()
        except Exception:  # another thread's: disabled by its own stop
            pass
    if role is None:
        argv = " ".join(sys.argv)
        role = "worker" if "studio.worker" in argv else "front" if "bench_studio" in argv else "other"
    stats = None
    for p in profiles:
        try:
            stats = pstats.Stats(p) if stats is None else stats.add(p)
        except TypeError:  # a profile with nothing in it
            pass
    if stats is not None:
        stats.dump_stats(os.path.join(_DIR, f"{role}-{os.getpid()}.prof"))


if _DIR:
    threading.setprofile(_start_thread)
    _main = cProfile.Profile()
    _profiles.append(_main)
    _main.enable()
    atexit.register(dump)
