"""Calls handed to an event loop from any thread, run there in the order handed, with one wake of the loop for all
that arrive before it runs them.

`loop.call_soon_threadsafe` writes the loop's self-pipe on every call: a studio worker whose stepping loop publishes
a frame for each of its rooms every round (and answers each room's move) woke its event loop once a room, a frame and
a move apiece (a system call and a wake each). The rooms of a worker share one loop, so their calls share one queue
here (`calls_for(loop)`): the first call since the loop last ran them wakes it, the others only join the queue, and
the loop runs every call queued when it wakes.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import logging
import threading
import weakref
from collections.abc import Callable

log = logging.getLogger(__name__)


class LoopCalls:
    """One event loop's queue of calls from any thread (see the module's docstring). `wakes`: the loop's wakes it
    asked for; `calls`: the calls handed."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self.loop = loop
        self._queue: collections.deque = collections.deque()
        self._lock = threading.Lock()
        self._scheduled = False
        self.wakes = 0
        self.calls = 0

    def call(self, fn: Callable, *args) -> None:
        """`fn(*args)` on the loop's thread after every call handed before it (from any thread, this one too); does
        nothing once the loop is closed. Inside `one_wake` the loop is woken when it ends."""
        with self._lock:
            self._queue.append((fn, args))
            self.calls += 1
            if self._scheduled:
                return
            held = getattr(_HELD, "loops", None)
            if held is not None:
                held.add(self)
                return
            self._scheduled = True
            self.wakes += 1
        self._wake()

    def wake(self) -> None:
        """Wake the loop for the calls waiting (none: nothing)."""
        with self._lock:
            if self._scheduled or not self._queue:
                return
            self._scheduled = True
            self.wakes += 1
        self._wake()

    def _wake(self) -> None:
        try:
            self.loop.call_soon_threadsafe(self._run)
        except RuntimeError:  # the loop is closed: the server is going down
            with self._lock:
                self._scheduled = False
                self._queue.clear()

    def _run(self) -> None:
        """The loop's thread: every call queued, those handed meanwhile too."""
        while True:
            with self._lock:
                if not self._queue:
                    self._scheduled = False
                    return
                fn, args = self._queue.popleft()
            try:
                fn(*args)
            except Exception:  # one call's failure must not strand the others
                log.exception("a call handed to the event loop failed")


_HELD = threading.local()  # .loops: the LoopCalls this thread handed calls to inside `one_wake`


@contextlib.contextmanager
def one_wake():
    """Calls this thread hands any loop inside wake it once, at the end (a studio worker's round: every room's frame
    and reply), not at the first; nested, the outermost ends it."""
    if getattr(_HELD, "loops", None) is not None:
        yield
        return
    _HELD.loops = loops = set()
    try:
        yield
    finally:
        _HELD.loops = None
        for calls in loops:
            calls.wake()


_BY_LOOP: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_BY_LOOP_LOCK = threading.Lock()


def calls_for(loop: asyncio.AbstractEventLoop) -> LoopCalls:
    """The one `LoopCalls` of `loop` (made on first use)."""
    with _BY_LOOP_LOCK:
        calls = _BY_LOOP.get(loop)
        if calls is None:
            with contextlib.suppress(TypeError):  # a loop that takes no weak reference gets its own each time
                calls = _BY_LOOP[loop] = LoopCalls(loop)
        return calls if calls is not None else LoopCalls(loop)


__all__ = ["LoopCalls", "calls_for", "one_wake"]
