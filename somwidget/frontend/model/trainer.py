"""The training thread of a session: data flows one way through it.

    view --intent--> Session (checks, changes its view at once) --Operation--> Trainer --som.step(k)--> Frame

Between two steps the thread applies every queued operation to the Som in order (several control moves that arrive
within one frame collapse into one `set_controls`), then steps k cycles, k sized so that a step takes about
`step_fraction / frame_rate` seconds, and publishes a frame. Once s reaches S (or while paused or held) it sleeps
until the next operation. The caller of an intent never waits for a training step.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

from ...backend.schedule import MAX_ITERATIONS
from .state import ModellingState
from .frames import Frame, FrameStream
from .operations import Operation, SetControls

log = logging.getLogger(__name__)


class Trainer:
    """The thread that trains one session's Som (see the module's docstring).

    make_frame(cycles): a frame of the Som now; after_turn(): called after each turn (the autosave's chance)."""

    def __init__(self, state: ModellingState, frames: FrameStream, make_frame: Callable[[int], Frame],
                 after_turn: Callable[[], None], frame_rate: float, step_fraction: float):
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
        self.cycle_time = 0.0
        self.cycles_per_step = 1

    # -- lifetime ----------------------------------------------------------------------------------------------
    def start(self) -> None:
        with self.state.lock:
            if self.closed:
                raise RuntimeError("session is closed")
            if self.thread is not None:
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
        if t is not None and t is not threading.current_thread():
            t.join(timeout)
        return not already

    def stopped(self) -> bool:
        """No more intents will be handled: closed, never started, or stopped on an error."""
        t = self.thread
        return self.closed or t is None or self.thread_error is not None or not t.is_alive()

    def reset_pace(self) -> None:
        self.cycle_time = 0.0
        self.cycles_per_step = 1

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

    def _loop(self) -> None:
        wake = self.state.wake
        while True:
            with wake:
                while not self.closed and not self.ops and not self.should_step():
                    self.busy = False
                    wake.notify_all()
                    wake.wait()
                if self.closed:
                    self.busy = False
                    wake.notify_all()
                    return
                self.busy = True
            t0 = time.monotonic()
            self._turn()
            self.after_turn()
            with wake:  # pace: a frame every 1 / frame_rate seconds while training; wake early for a new intent
                if self.should_step() and not self.ops and not self.closed:
                    rest = 1.0 / self.frame_rate - (time.monotonic() - t0)
                    if rest > 0:
                        wake.wait(rest)

    def _turn(self) -> None:
        """Apply the queued operations, step, publish a frame. Never raises."""
        try:
            frame = self._apply_and_step()
        except Exception as exc:  # keep the thread alive; views show the error
            log.exception("training step failed")
            frame = self._error_frame(f"training failed: {exc}")
        if frame is not None:
            self.frames.publish(frame)

    def _apply_and_step(self) -> Frame:
        state = self.state
        with state.som_lock:
            drained = self.drain()
            som = state.som
            cycles = 0
            with state.lock:
                stepping = self.should_step()
                dragging = state.gesture
            if stepping:
                k = self.cycles_per_step
                if drained and not dragging:  # a fresh intent: a short first step gets the change out sooner
                    k = max(1, k // 4)
                k = max(1, min(k, som.iterations - som.iteration))
                t = time.perf_counter()
                cycles = som.step(k)
                if hasattr(som, "synchronize"):
                    som.synchronize()
                dt = time.perf_counter() - t
                if cycles > 0:
                    self._tune(dt / cycles)
                    state.unsaved = True
            return self.make_frame(cycles)

    def _tune(self, per_cycle: float) -> None:
        per_cycle = max(per_cycle, 1e-7)
        self.cycle_time = per_cycle if self.cycle_time == 0.0 else 0.7 * self.cycle_time + 0.3 * per_cycle
        budget = self.step_fraction / self.frame_rate
        target = int(budget / self.cycle_time)
        # grow at most x2 a frame so one slow first call does not overshoot
        self.cycles_per_step = max(1, min(target, 2 * self.cycles_per_step, MAX_ITERATIONS))

    def _error_frame(self, message: str) -> Frame | None:
        """After a failed step: pause, show `message`, and return a frame to publish. Never raises."""
        state = self.state
        try:
            with state.lock:
                state.error = message
                state.paused = True
            try:
                with state.som_lock:
                    return self.make_frame(0)
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
                if not (self.ops or self.busy or (t is not None and self.should_step())):
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
            target = self.enqueued
            while self.frames.latest.applied < target:
                if self.stopped():
                    return False
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                wake.wait(min(left, 0.05))
        return True
