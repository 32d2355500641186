"""One stepping loop for every room of a worker: the rooms' sessions have no training thread of their own (their
trainers' `driver` is this loop, model/trainer.py), so no thread a room waits its turn for the process's Warp lock.

A room's slow posted calls (a preset switch, a refine, an undo, a save: any but the quick ones, Trainer.post) run on
threads of their own, the room without a turn until they ran, so that the other rooms' rounds go on meanwhile.
A round: each room with work runs its quick posted calls (a move, a grab), then (under its Som lock) applies its queued
operations and chooses its cycles (`Trainer.prepare`); rooms alike (batched.py: `batch_key`) are held in their batch and
stepped in one launch a batch, the others step by themselves at once; each room then gets its frame (from its row of the
batch's one copy of the weights: `Trainer.end_step`) and its autosave's turn. A room is in a round when an intent
reached it since its last turn, or when it trains and its last turn was a frame's time ago (the rooms' frame rate): so a
move is answered by the next round, which starts as soon as one is poked (at most one every MIN_GAP seconds), and rooms
that only train get a frame `frame_rate` times a second. Alike rooms step batched from the round after two or more of
them stepped in one round, and a room held stays in its batch when it steps alone (no copies back and forth); a room of
a kind no other room steps with steps by itself (its own path, its graphs).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor

from ..model.trainer import step_alone
from ..web.loop_calls import one_wake
from .batched import BatchedRooms, RoomLock, applies_in_batch, keeps_key

log = logging.getLogger(__name__)

#: The least time between the starts of two rounds (s): moves that arrive meanwhile share the next.
MIN_GAP = 0.004
#: Rooms that train are in a round this much before their frame's time is up (s).
EARLY = 0.002
#: How long an idle loop waits before it looks at its rooms again without being poked (s).
IDLE_LOOK = 0.25
#: Threads that run rooms' slow calls (a preset switch, a refine, an undo, a save) off the loop.
CALL_THREADS = 4
#: Rounds whose durations `timings` reports (the latest; about 10 s of a busy loop).
TIMED_ROUNDS = 2048


class Rounds:
    """The loop (see the module's docstring) over the rooms' trainers that `add` hands it. `rounds`: rounds run."""

    def __init__(self, batches: BatchedRooms, frame_rate: float) -> None:
        self.batches = batches
        self.period = 1.0 / frame_rate
        self._trainers: dict[int, object] = {}
        self._last: dict[int, float] = {}  # id(trainer) -> when its last turn began
        self._lock = threading.Lock()
        self._poked = threading.Event()
        self._stopped = False
        self._counts: dict[tuple, int] = {}  # rooms of each batch key stepped in the last round
        self._keys: dict[int, tuple] = {}  # id(trainer) -> (its Som, its batch key): found again when either changes
        self._calling: set[int] = set()  # rooms whose slow calls run off the loop: no turn meanwhile
        self._calls = ThreadPoolExecutor(CALL_THREADS, thread_name_prefix="somwidget-room-calls")
        self.thread = threading.Thread(target=self._run, name="somwidget-rounds", daemon=True)
        self.rounds = 0
        self._durations: deque[float] = deque(maxlen=TIMED_ROUNDS)  # s, the latest rounds' (with rooms in them)

    # -- rooms come and go --------------------------------------------------------------------------------------
    def add(self, trainer) -> threading.Thread:
        """Run `trainer`'s turns from now on (its `start`); the loop's thread."""
        state = trainer.state
        state.som_lock = state.lent = RoomLock(state.som_lock, lambda: self.batches.give_back(trainer),
                                               lambda: self.batches.state_to_save(trainer))

        def before_apply(ops) -> None:
            if not all(applies_in_batch(op) for op in ops):
                self.batches.give_back(trainer)
            kept = self._keys.get(id(trainer))
            if kept is not None and not all(keeps_key(op, kept[1]) for op in ops):
                self._keys.pop(id(trainer), None)

        trainer.before_apply = before_apply
        with self._lock:
            self._trainers[id(trainer)] = trainer
            if not self.thread.is_alive() and not self._stopped:
                self.thread.start()
        self.poke()
        return self.thread

    def remove(self, trainer) -> None:
        """No more turns for `trainer` (closed): its Som gets its state back (its Som lock, at the end of a turn
        under way)."""
        with self._lock:
            self._trainers.pop(id(trainer), None)
            self._last.pop(id(trainer), None)
            self._keys.pop(id(trainer), None)
        with trainer.state.som_lock:  # RoomLock: given back
            pass

    def timings(self) -> dict:
        """The latest rounds (TIMED_ROUNDS at most): how many, their median, 95th percentile and longest (ms)."""
        ms = sorted(1e3 * d for d in list(self._durations))
        if not ms:
            return {"rounds": 0}
        return {"rounds": len(ms), "median_ms": round(ms[len(ms) // 2], 2),
                "p95_ms": round(ms[min(len(ms) - 1, int(0.95 * len(ms)))], 2), "max_ms": round(ms[-1], 2)}

    def poke(self) -> None:
        """An intent arrived: the next round soon."""
        self._poked.set()

    def stop(self) -> None:
        self._stopped = True
        self._poked.set()
        if self.thread.is_alive() and self.thread is not threading.current_thread():
            self.thread.join(10)
        self._calls.shutdown(wait=False)

    # -- the loop -----------------------------------------------------------------------------------------------
    def _run(self) -> None:
        while not self._stopped:
            self._poked.clear()
            began = time.monotonic()
            try:
                due = self._round(began)
            except Exception:  # pragma: no cover - a bug here must not stop every room
                log.exception("studio: a round failed")
                due = began + self.period
            self.rounds += 1
            if self._trainers:
                self._durations.append(time.monotonic() - began)
            wait = IDLE_LOOK if due is None else due - time.monotonic()
            if wait > 0:
                self._poked.wait(wait)
            gap = began + MIN_GAP - time.monotonic()
            if gap > 0:
                time.sleep(gap)

    def _round(self, now: float) -> float | None:
        """One round (the module's docstring); when the next is due (None: no room trains). What the rooms hand
        their event loop (the calls' replies, then the frames) wakes it once for all of them (web/loop_calls.py):
        a wake a room handed the loop the interpreter's lock mid-round, room after room."""
        with self._lock:
            trainers = list(self._trainers.values())
        with one_wake():  # the calls' replies handed before the steps (no pause for them: the loop takes its turn)
            turns = [trainer for trainer in trainers if self._wants_turn(trainer, now)]
        with one_wake():
            return self._turns(trainers, turns, now)

    def _turns(self, trainers: list, turns: list, now: float) -> float | None:
        """The rooms' turns of a round (`turns`: those that have one); when the next round is due."""
        due: float | None = None
        asks = []  # (trainer, cycles): the held rooms' steps, one launch a batch
        counts: dict[tuple, int] = {}  # rooms of each batch key this round
        for trainer in turns:
            self._last[id(trainer)] = now
            lock = trainer.state.som_lock
            if not lock.turn(blocking=False):  # an undo, a save meanwhile: next round
                due = now + MIN_GAP
                continue
            frame = None
            try:
                cycles = trainer.prepare()
                som = trainer.state.som
                key = self._key(trainer, som) if cycles else None
                if key is not None:
                    counts[key] = counts.get(key, 0) + 1
                if key is not None and (self._counts.get(key, 0) >= 2 or self.batches.holds(trainer)):
                    self.batches.hold(trainer, som, key)
                    asks.append((trainer, cycles))
                    continue
                self.batches.give_back(trainer)
                t = time.perf_counter()
                ran = step_alone(som, cycles) if cycles else 0
                frame = trainer.end_step(ran, time.perf_counter() - t)
            except Exception as exc:  # the room shows it; the others go on
                trainer.fail_turn(exc)
            finally:
                lock.release()
            self._finish(trainer, frame)
        self._counts = counts
        results = self.batches.step(asks) if asks else {}
        for trainer, _ in asks:
            lock = trainer.state.som_lock
            lock.turn()
            frame = None
            try:
                got = results.get(trainer, (0, 0.0))
                if isinstance(got, BaseException):
                    raise got
                held = self.batches.holds(trainer)
                weights = self.batches.host(trainer) if held else None
                colours = self.batches.colours(trainer, trainer.state.preset.layout) if held else None
                frame = trainer.end_step(got[0], got[1], weights, colours)
            except Exception as exc:
                trainer.fail_turn(exc)
            finally:
                lock.release()
            self._finish(trainer, frame)
        for trainer in trainers:
            with trainer.state.wake:
                trains = not trainer.closed and trainer.should_step()
            if trains:
                when = self._last.get(id(trainer), now) + self.period - EARLY
                due = when if due is None else min(due, when)
        return due

    def _key(self, trainer, som) -> tuple | None:
        """The room's batch key (batched.batch_key), found again only when its Som or its settings changed."""
        kept = self._keys.get(id(trainer))
        if kept is None or kept[0] is not som:
            kept = self._keys[id(trainer)] = (som, self.batches.key(som))
        return kept[1]

    def _wants_turn(self, trainer, now: float) -> bool:
        """Whether `trainer` has a turn this round (its quick posted calls run first; a slow one sends the room's
        calls off the loop, and the room has no turn until they ran: `_call_off_loop`)."""
        if trainer.closed or id(trainer) in self._calling:
            return False
        ran = trainer.run_calls(quick_only=True, pause=False) if trainer.calls else False
        if trainer.calls:  # a slow call: the other rooms do not wait for it
            self._call_off_loop(trainer)
            return False
        with trainer.state.wake:
            if trainer.ops:
                trainer.busy = True
                return True
            if trainer.should_step():
                trainer.busy = True
                return self._last.get(id(trainer), 0.0) + self.period - EARLY <= now
        if ran:
            self._keys.pop(id(trainer), None)
            trainer.after_turn()
        self._idle(trainer)
        return False

    def _call_off_loop(self, trainer) -> None:
        """Run the room's posted calls on a thread of their own (in order, with the quick ones behind them); the room's
        turns wait for them, then the loop is poked."""
        with trainer.state.wake:
            trainer.busy = True  # wait_idle: a call is under way
        self._calling.add(id(trainer))
        self._keys.pop(id(trainer), None)  # a call may change the Som's settings

        def run() -> None:
            try:
                trainer.run_calls()
                with trainer.state.wake:
                    idle = not trainer.ops and not trainer.should_step()
                if idle:  # a step completed that trains nothing: the autosave's turn
                    trainer.after_turn()
            except Exception:  # pragma: no cover - each call's Future holds its own exception
                log.exception("studio: a room's calls failed")
            finally:
                self._keys.pop(id(trainer), None)
                self._calling.discard(id(trainer))
                self._idle(trainer)
                self.poke()

        try:
            self._calls.submit(run)
        except RuntimeError:  # stopped: the room's calls fail as the room closes
            self._calling.discard(id(trainer))

    @staticmethod
    def _idle(trainer) -> None:
        wake = trainer.state.wake
        with wake:
            if trainer.busy and not trainer.has_work():
                trainer.busy = False
                wake.notify_all()

    def _finish(self, trainer, frame) -> None:
        trainer.publish(frame)
        try:
            trainer.after_turn()
        except Exception:  # pragma: no cover - the autosave reports its own failures
            log.exception("studio: a room's autosave failed")
        self._idle(trainer)


__all__ = ["Rounds", "MIN_GAP"]
