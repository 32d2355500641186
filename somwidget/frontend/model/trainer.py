"""The training thread of a session: data flows one way through it.

    view --intent--> Session (checks, changes its view at once) --Operation--> Trainer --som.step(k)--> Frame

Between two steps the thread applies every queued operation to the Som in order (several control moves that arrive
within one frame collapse into one `set_controls`), then steps k cycles, k sized so that a step takes about
`step_fraction / frame_rate` seconds, and publishes a frame. A cycle early in the schedule (after a restart: a drag's
frames, a setting) costs far more than one late in a long run, so the steps after a restart are sized apart
(`Pace`): a drag's first frame stays within a frame's time. Once s reaches S (or while paused or held) it sleeps
until the next operation. The caller of an intent never waits for a training step.

A caller that must not wait even for the Som's lock (a server's event loop) posts its intents instead (`post`): the
thread runs them in order between two turns, where nothing else holds the lock.

A driver (a studio worker's stepping loop, studio/rounds.py) may run the turns of many sessions from one thread
instead: `start` then hands the session to it, and it calls `run_calls`, `prepare` (the operations applied, the
cycles wanted), steps them (with other sessions' in one launch), then `end_step` (the frame) and `after_turn`.
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from typing import Protocol

import numpy as np

from ...backend.schedule import MAX_ITERATIONS
from .frames import Frame, FrameStream
from .operations import Operation, SetControls
from .state import ModellingState

log = logging.getLogger(__name__)


class Pace:
    """Cycles a step, sized to a step's time budget from the time a cycle took (a moving average)."""

    def __init__(self) -> None:
        self.cycle_time = 0.0
        self.cycles = 1

    def tune(self, per_cycle: float, budget: float) -> None:
        per_cycle = max(per_cycle, 1e-7)
        self.cycle_time = per_cycle if self.cycle_time == 0.0 else 0.7 * self.cycle_time + 0.3 * per_cycle
        target = int(budget / self.cycle_time)
        # grow at most x2 a frame so one slow first call does not overshoot
        self.cycles = max(1, min(target, 2 * self.cycles, MAX_ITERATIONS))


class TurnDriver(Protocol):
    """A loop that runs the turns of many sessions from one thread (a studio worker's, studio/rounds.py): `add(trainer)`
    runs its turns from now on and returns the loop's thread; `remove(trainer)`: no more (closed); `poke()`: an intent
    arrived, a turn soon."""

    def add(self, trainer: Trainer) -> threading.Thread: ...

    def remove(self, trainer: Trainer) -> None: ...

    def poke(self) -> None: ...


class Trainer:
    """The thread that trains one session's Som (see the module's docstring).

    make_frame(cycles, weights, colours): a frame of the Som now (`weights` and their nodes' `colours`: where a batch
    holds them, else None);
    after_turn(): called after each turn (the autosave's chance)."""

    def __init__(self, state: ModellingState, frames: FrameStream,
                 make_frame: Callable[[int, np.ndarray | None, np.ndarray | None], Frame],
                 after_turn: Callable[[], None],
                 frame_rate: float, step_fraction: float) -> None:
        self.state = state
        self.frames = frames
        self.make_frame = make_frame
        self.after_turn = after_turn
        self.frame_rate = frame_rate
        self.step_fraction = step_fraction
        self.ops: list[tuple[Operation, int]] = []  # (operation, number of its intent)
        self.enqueued = 0  # intents queued so far; each operation carries its number
        self.applied = 0  # intents handled (Frame.applied)
        self.thread: threading.Thread | None = None
        self.thread_error: str | None = None  # why the thread stopped, if it ever did on an error
        self.closed = False
        self.busy = False  # applying operations or stepping
        self.pace = Pace()  # steps that go on with the schedule
        self.restart_pace = Pace()  # steps right after a restart took the schedule back
        self._stepped_to = 0  # the iteration the last step reached
        self.calls: collections.deque = collections.deque()  # (call, Future, quick): posted, run between two turns
        self.posted = 0  # calls posted so far
        self.ran = 0  # calls run so far
        #: The loop that runs this session's turns with others' (studio/rounds.py); None: a thread of its own
        self.driver: TurnDriver | None = None
        #: Called with the operations `drain` takes, before it applies them (a studio's room: its Som's state back from
        #: the batch that holds it, unless the batch can apply them too: studio/batched.py)
        self.before_apply: Callable[[list[Operation]], None] | None = None
        self._pace_now = self.pace  # the pace `prepare` chose

    # -- lifetime ----------------------------------------------------------------------------------------------
    def start(self) -> None:
        with self.state.lock:
            if self.closed:
                raise RuntimeError("session is closed")
            if self.thread is not None:
                return
            if self.driver is not None:
                self.thread = self.driver.add(self)
                return
            self.thread = threading.Thread(target=self._run, name="somwidget-session", daemon=True)
            self.thread.start()

    def close(self, timeout: float) -> bool:
        """Stop the thread; False if it was closed already."""
        with self.state.wake:
            already = self.closed
            self.closed = True
            self.state.wake.notify_all()
        t = self.thread
        if self.driver is not None and t is not None:
            self.driver.remove(self)
            self._fail_calls("session is closed")
        elif t is not None and t is not threading.current_thread():
            t.join(timeout)
        return not already

    def post(self, call: Callable[[], object], quick: bool = False) -> Future:
        """Run `call()` on the training thread between two turns, after the calls posted before it; returns its Future
        (its result, or the exception it raised). Without a running thread (never started) it runs here and now; on a
        closed session (or a thread stopped on an error) the Future holds a RuntimeError. `quick`: a call that takes
        no time (a move, a grab: a studio's loop runs it in its round; any other runs off the loop, rounds.py)."""
        future: Future = Future()
        with self.state.wake:
            if self.closed or self.thread_error is not None:
                future.set_exception(RuntimeError(self.thread_error or "session is closed"))
                return future
            if self.thread is not None and self.thread.is_alive():
                self.calls.append((call, future, quick))
                self.posted += 1
                self.state.wake.notify_all()
                self._poke()
                return future
        _run(call, future)
        return future

    def _poke(self) -> None:
        if self.driver is not None:
            self.driver.poke()

    def run_calls(self, quick_only: bool = False, pause: bool = True) -> bool:
        """The posted calls, in order (on the training thread, holding no lock), with `quick_only` up to the first
        that is not quick; then (`pause`) a moment for the threads that wait on them (their replies go out before the
        next step: a driver of many sessions pauses once for all of them). Whether any ran."""
        ran = False
        while True:
            with self.state.wake:
                if not self.calls or (quick_only and not self.calls[0][2]):
                    if ran and pause:
                        time.sleep(0)
                    return ran
                call, future, _ = self.calls.popleft()
            ran = True
            _run(call, future)
            with self.state.wake:
                self.ran += 1
                self.state.wake.notify_all()

    def _fail_calls(self, why: str) -> None:
        with self.state.wake:
            calls, self.calls = list(self.calls), collections.deque()
            self.ran += len(calls)
        for _, future, _ in calls:
            future.set_exception(RuntimeError(why))

    def stopped(self) -> bool:
        """No more intents will be handled: closed, never started, or stopped on an error."""
        t = self.thread
        return self.closed or t is None or self.thread_error is not None or not t.is_alive()

    def reset_pace(self) -> None:
        self.pace, self.restart_pace = Pace(), Pace()

    @property
    def cycle_time(self) -> float:
        """Seconds per cycle as the schedule goes on (moving average; 0 before any step)."""
        return self.pace.cycle_time

    # -- the queue ---------------------------------------------------------------------------------------------
    def enqueue(self, op: Operation, intent: bool = True) -> None:
        """Queue an operation (caller holds state.lock). An intent gets the next number; the session's own operations
        (intent False: a frame to publish) share the latest one."""
        if self.closed:
            raise RuntimeError("session is closed")
        self.enqueued += int(intent)
        entry = (op, self.enqueued)
        if isinstance(op, SetControls) and self.ops and isinstance(self.ops[-1][0], SetControls):
            self.ops[-1] = (op.after(self.ops[-1][0]), self.enqueued)  # several moves within a frame: the latest
        else:
            self.ops.append(entry)
        self.busy = True
        self.state.wake.notify_all()
        self._poke()

    def discard_queued(self) -> None:
        """Forget the queued operations, as handled (caller holds both locks: they belonged to a mesh that goes)."""
        self.ops.clear()
        self.applied = self.enqueued

    def drain(self) -> bool:
        """Apply every queued operation to the Som, in order (caller holds state.som_lock); True if there were any."""
        state = self.state
        with state.lock:  # taken under the Som lock: a preset installed in between cannot strand these operations
            ops, self.ops = self.ops, []
            if ops:  # handled from here on, whatever happens: every later frame is made after them
                self.applied = max(self.applied, ops[-1][1])
                state.unsaved = True
        if ops and self.before_apply is not None:
            self.before_apply([op for op, _ in ops])
        for i, (op, _number) in enumerate(ops):
            self._apply(op, ops[i + 1:])
        return bool(ops)

    def _apply(self, op: Operation, later) -> None:
        """Apply one operation; if the engine refuses it, roll the session's view back (unless a later operation
        of the same key sets it again), record the error and carry on."""
        state, som = self.state, self.state.som
        try:
            if op.acts:
                with state.lock:
                    state.hold = False  # the person acted: training goes on
            op.apply(som)
            with state.lock:
                op.applied(state)
        except Exception as exc:
            log.warning("%s refused by the engine: %s", type(op).__name__, exc)
            with state.lock:
                pending = {o.key for o, _ in later} | {o.key for o, _ in self.ops}
                try:
                    if op.key is not None and op.key not in pending:
                        op.roll_back(state, som)
                except Exception:  # pragma: no cover - the Som's getters do not fail
                    log.exception("could not roll back %s", op)
                state.error = f"the engine refused {op.key or type(op).__name__.lower()}: {exc}"

    def should_step(self) -> bool:
        """Training has work (caller holds state.lock): not paused, not held, s < S."""
        state = self.state
        return not state.paused and not state.hold and state.som.iteration < state.som.iterations

    def has_work(self) -> bool:
        """Calls, operations or cycles wait (caller holds state.lock)."""
        return bool(self.calls or self.ops) or self.should_step()

    # -- the thread --------------------------------------------------------------------------------------------
    def _run(self) -> None:
        state = self.state
        try:
            self._loop()
        except BaseException as exc:  # a bug in the session itself: never die silently
            log.exception("the session's training thread stopped")
            with state.wake:
                self.thread_error = f"training thread stopped: {type(exc).__name__}: {exc}"
                state.paused = True
                self.busy = False
                state.wake.notify_all()
            self._fail_calls(self.thread_error)

    def _loop(self) -> None:
        wake = self.state.wake
        while True:
            with wake:
                while not self.closed and not self.calls and not self.ops and not self.should_step():
                    self.busy = False
                    wake.notify_all()
                    wake.wait()
                if self.closed:
                    self.busy = False
                    wake.notify_all()
                    break
                self.busy = True
            self.run_calls()
            with wake:
                idle = not self.ops and not self.should_step()
            if idle:  # a call may have completed a step that trains nothing (a bare release): the autosave's turn
                self.after_turn()
                continue
            t0 = time.monotonic()
            self._turn()
            self.after_turn()
            with wake:  # pace: a frame every 1 / frame_rate seconds while training; wake early for a new intent
                if self.should_step() and not self.ops and not self.calls and not self.closed:
                    rest = 1.0 / self.frame_rate - (time.monotonic() - t0)
                    if rest > 0:
                        wake.wait(rest)
        self._fail_calls("session is closed")

    def _turn(self) -> None:
        """Apply the queued operations, step, publish a frame. Never raises."""
        frame: Frame | None
        try:
            frame = self._apply_and_step()
        except Exception as exc:  # keep the thread alive; views show the error
            log.exception("training step failed")
            frame = self._error_frame(f"training failed: {exc}")
        if frame is not None:
            self.frames.publish(frame)

    def _apply_and_step(self) -> Frame:
        with self.state.som_lock:
            k = self.prepare()
            cycles, t = 0, time.perf_counter()
            if k:
                cycles = step_alone(self.state.som, k)
            return self.end_step(cycles, time.perf_counter() - t)

    def prepare(self) -> int:
        """A turn's first half (caller holds state.som_lock): the queued operations applied; the cycles to step now
        (0: none, a frame only), sized by the pace."""
        state = self.state
        drained = self.drain()
        som = state.som
        with state.lock:
            stepping = self.should_step()
            dragging = state.gesture
        if not stepping:
            return 0
        pace = self._pace_now = self.restart_pace if som.iteration < self._stepped_to else self.pace
        k = pace.cycles
        if drained and not dragging:  # a fresh intent: a short first step gets the change out sooner
            k = max(1, k // 4)
        return max(1, min(k, som.iterations - som.iteration))

    def end_step(self, cycles: int, seconds: float, weights: np.ndarray | None = None,
                 colours: np.ndarray | None = None) -> Frame:
        """A turn's second half (caller holds state.som_lock): `cycles` ran in `seconds`; the frame of the Som now
        (`weights`: its weights, where a batch holds them, and `colours` their nodes' colours, made for every room
        of the batch at once: studio/batched.py)."""
        if cycles > 0:
            self._pace_now.tune(seconds / cycles, self.step_fraction / self.frame_rate)
            with self.state.lock:
                self.state.unsaved = True
        self._stepped_to = self.state.som.iteration
        return self.make_frame(cycles, weights, colours)

    def publish(self, frame: Frame | None) -> None:
        if frame is not None:
            self.frames.publish(frame)

    def fail_turn(self, exc: BaseException) -> None:
        """A turn that failed (a driver's launch): pause, show why, publish a frame. Never raises."""
        log.error("training step failed: %s", exc)
        self.publish(self._error_frame(f"training failed: {exc}"))

    def _error_frame(self, message: str) -> Frame | None:
        """After a failed step: pause, show `message`, and return a frame to publish. Never raises."""
        state = self.state
        try:
            with state.lock:
                state.error = message
                state.paused = True
            try:
                with state.som_lock:
                    return self.make_frame(0, None, None)
            except Exception:
                log.exception("could not make a frame after the error")
            with state.lock:  # the last frame again, marked paused, with the intents handled since
                return self.frames.again(self.frames.latest, applied=self.applied, running=False, paused=True,
                                         step_cycles=0)
        except Exception:  # pragma: no cover - nothing above should fail
            log.exception("could not publish the error")
            return None

    # -- waiting -----------------------------------------------------------------------------------------------
    def wait_idle(self, timeout: float) -> bool:
        """Block until every queued intent is applied and training has stopped (s = S or paused); False at the
        timeout, and at once if the thread has stopped on an error."""
        deadline = time.monotonic() + timeout
        wake = self.state.wake
        with wake:
            while True:
                t = self.thread
                if self.thread_error is not None or (t is not None and not self.closed and not t.is_alive()):
                    return False
                if not (self.calls or self.ops or self.busy or (t is not None and self.should_step())):
                    return True
                if t is None or self.closed:
                    return not self.ops
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                wake.wait(min(left, 0.05))

    def wait_applied(self, timeout: float) -> bool:
        """Block until every intent queued so far has reached the Som and a published frame shows it; False at the
        timeout, and at once if the thread is not running."""
        deadline = time.monotonic() + timeout
        wake = self.state.wake
        with wake:
            posted = self.posted  # the calls posted so far first: the intents they queue count too
            while self.ran < posted:
                if self.stopped():
                    return False
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                wake.wait(min(left, 0.05))
            target = self.enqueued
            while self.frames.latest.applied < target:
                if self.stopped():
                    return False
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                wake.wait(min(left, 0.05))
        return True


def step_alone(som, cycles: int) -> int:
    """Step the Som `cycles` cycles by itself, waiting for the device; the cycles run."""
    ran = som.step(cycles)
    if hasattr(som, "synchronize"):
        som.synchronize()
    return ran


def _run(call: Callable[[], object], future: Future) -> None:
    """`call()` into `future` (never raises)."""
    if not future.set_running_or_notify_cancel():
        return
    try:
        future.set_result(call())
    except BaseException as exc:  # the caller's to see
        future.set_exception(exc)
