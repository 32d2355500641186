"""Who is on a session, and which controls each holds: the hands. One registry per session, shared by every view (a
desktop page, a notebook, a headset: each view's connection is a hand) and by Python (`Hands.python`: scripts and
panels).

A control is held by one hand at a time, from its grab to its release. Every other hand is refused it (a grab, a
move, a radius, a removal) with a message that names the holder. A grab opens the hand's gesture on that control
(gestures.py: one undo step from grab to release, whatever the other hands do meanwhile). A hand that goes (its view
closed) or stays silent for SILENT_SECONDS while it holds something lets go of all it holds, each drag a completed
step; a hand whose control is removed or replaced loses that grab. Python holds the controls a script's
`with session.gesture():` changes until the gesture ends.

Listeners (`subscribe`) hear of every change, with the grabs lost (hand, control id, why): the transport tells every
view who is there and who holds what (transport/holders.py).

A person's undo (`undo_own`) takes back that person's latest step first (gestures.py), Python's undo the whole
history.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from .gestures import PYTHON, acting, actor
from .operations import Grab, Release

#: What a view is, as the others see it.
KINDS = ("desktop", "notebook", "headset")
#: The hands' colours, one each in the order they come: distinct on the clay's light background and in a headset, and
#: none red (a view draws the control it holds itself red).
COLOURS = ("#4363d8", "#2e8b3e", "#f58231", "#911eb4", "#1a9fb3", "#d6329c", "#7f8c1b", "#9a6324", "#000075",
           "#469990")
PYTHON_COLOUR = "#555555"
#: A hand that holds a control and sends nothing for this long lets go (a view keeps saying it is there while it
#: holds: client/src/grabs.js pings every 2 s).
SILENT_SECONDS = 10.0


class Hand:
    """One hand on a session: a view (its kind, a colour, the person's name where they gave one) or Python."""

    __slots__ = ("id", "kind", "colour", "person")

    def __init__(self, id: int, kind: str, colour: str) -> None:
        self.id, self.kind, self.colour = id, kind, colour
        self.person = ""

    @property
    def name(self) -> str:
        return "Python" if self.kind == "python" else self.person or f"{self.kind} {self.id}"

    def __repr__(self) -> str:
        return f"Hand({self.name})"


@dataclass(frozen=True)
class Lost:
    """A grab that ended without its hand's release: whose, which control, and why (a message for that hand)."""

    hand: Hand
    control_id: int
    why: str


def check_kind(kind) -> str:
    if kind not in KINDS:
        raise ValueError(f"hand: unknown kind {kind!r}; known: {', '.join(KINDS)}")
    return kind


class Hands:
    """The hands of one session and what each holds (see the module's docstring). `clay`: the session's shared state
    (its control ids); `timeline`: where each grab's gesture opens and completes."""

    def __init__(self, state, timeline) -> None:
        self.state = state
        self.timeline = timeline
        self.python = Hand(PYTHON, "python", PYTHON_COLOUR)
        self._lock = threading.RLock()
        self._here: dict[int, Hand] = {}  # the views' hands, in the order they came
        self._held: dict[int, Hand] = {}  # control id -> the hand holding it
        self._heard: dict[int, float] = {}  # hand id -> when it last sent something
        self._script = False  # Python's gesture is open
        self._next = 1
        self._listeners: list[Callable[[list[Lost]], None]] = []

    # -- who is here ---------------------------------------------------------------------------------------------
    def join(self, kind: str) -> Hand:
        """A view came: its hand, with the next colour."""
        check_kind(kind)
        with self._lock:
            hand = Hand(self._next, kind, COLOURS[(self._next - 1) % len(COLOURS)])
            self._next += 1
            self._here[hand.id] = hand
            self._heard[hand.id] = time.monotonic()
        self._tell()
        return hand

    def set_kind(self, hand: Hand, kind: str, person: str | None = None) -> None:
        """A view says what it is now (a headset's page entering or leaving its immersive session), and who uses it
        where the person gave their name (None: as it was)."""
        check_kind(kind)
        person = hand.person if person is None else person
        if (hand.kind, hand.person) != (kind, person):
            hand.kind, hand.person = kind, person
            self._tell()

    def leave(self, hand: Hand) -> None:
        """A view went: what it held is let go, each drag a completed step."""
        with self._lock:
            self._here.pop(hand.id, None)
            self._heard.pop(hand.id, None)
        self._let_go([(cid, hand) for cid, who in self.held().items() if who is hand], [])

    def acting(self, hand: Hand, control_id: int | None = None):
        """A context in which the intents run are `hand`'s (on `control_id`: a drag's moves join its gesture)."""
        return acting(hand.id, control_id)

    def heard(self, hand: Hand) -> None:
        """`hand` sent something: it is still there."""
        self._heard[hand.id] = time.monotonic()

    def present(self) -> list[tuple[Hand, tuple[int, ...]]]:
        """Each hand here (Python while it holds something) with the ids of the controls it holds."""
        with self._lock:
            hands = list(self._here.values())
            held = dict(self._held)
        if any(who is self.python for who in held.values()):
            hands.insert(0, self.python)
        return [(h, tuple(sorted(cid for cid, who in held.items() if who is h))) for h in hands]

    def held(self) -> dict[int, Hand]:
        """Control id -> the hand holding it."""
        with self._lock:
            return dict(self._held)

    def holder(self, control_id: int) -> Hand | None:
        return self._held.get(control_id)

    # -- holding -------------------------------------------------------------------------------------------------
    def grab(self, hand: Hand, control_id: int) -> None:
        """`hand` holds the control: its drag (one undo step) begins. ValueError while another hand holds it, or
        when the control is gone."""
        index = self._index(control_id)
        with self._lock:
            holder = self._held.get(control_id)
            if holder is not None and holder is not hand:
                raise ValueError(refusal("grab", index, holder))
            self._held[control_id] = hand
        if holder is None:
            self.timeline.begin_gesture((hand.id, control_id))
            self._engine(Grab, [control_id])
            self._tell()

    def check_holds(self, hand: Hand, control_id: int, what: str) -> None:
        """ValueError unless `hand` holds the control (a view's move or release)."""
        holder = self._held.get(control_id)
        if holder is not hand:
            index = self._index(control_id, default=control_id)
            if holder is not None:
                raise ValueError(refusal(what, index, holder))
            raise ValueError(f"{what}: control {index} is not held by this client; send grab first")

    def release(self, hand: Hand, control_id: int) -> bool:
        """`hand` lets go of the control: its drag is a completed step. False when it did not hold it."""
        with self._lock:
            if self._held.get(control_id) is not hand:
                return False
            del self._held[control_id]
        self._engine(Release, [control_id])
        self.timeline.end_gesture((hand.id, control_id))
        self._tell()
        return True

    def claim(self, index: int | None = None, control_id: int | None = None) -> None:
        """Before an intent changes one control (by index or id): refused while a hand other than the one acting
        holds it; inside a script's gesture Python holds it until the gesture ends."""
        hand_id, _ = actor()
        if control_id is None:
            with self.state.lock:
                ids = self.state.control_ids
                if not isinstance(index, int) or not 0 <= index < len(ids):
                    return  # the intent's own checks say what is wrong
                control_id = ids[index]
        with self._lock:
            holder = self._held.get(control_id)
            if holder is not None and holder.id != hand_id:
                raise ValueError(refusal("change", self._index(control_id), holder))
            take = holder is None and hand_id == PYTHON and self._script
            if take:
                self._held[control_id] = self.python
        if take:
            self._engine(Grab, [control_id])
            self._tell()

    def begin_script(self) -> None:
        """Python's gesture opens (`with session.gesture():`)."""
        with self._lock:
            self._script = True
        self.timeline.begin_gesture((PYTHON, None))

    def end_script(self) -> None:
        """Python's gesture completes: what it held is free again."""
        with self._lock:
            self._script = False
            mine = [cid for cid, who in self._held.items() if who is self.python]
            for cid in mine:
                del self._held[cid]
        self._engine(Release, mine)
        self.timeline.end_gesture((PYTHON, None))
        if mine:
            self._tell()

    # -- letting go ------------------------------------------------------------------------------------------------
    def prune(self) -> None:
        """Grabs of controls that are gone (removed, replaced, a preset or an undo) end; each holder is told."""
        with self.state.lock:
            ids = set(self.state.control_ids)
        held = self.held()
        gone = [(cid, who) for cid, who in held.items() if cid not in ids]
        if gone:
            self._let_go(gone, [Lost(who, cid, f"control {cid} was removed while you held it: the drag ended")
                                for cid, who in gone])

    def quiet(self, seconds: float = SILENT_SECONDS) -> None:
        """The hands that hold something and were silent for `seconds` let go of it all; each is told."""
        now = time.monotonic()
        with self._lock:
            silent = [(cid, who) for cid, who in self._held.items()
                      if who is not self.python and now - self._heard.get(who.id, now) > seconds]
        if silent:
            self._let_go(silent, [Lost(who, cid, f"you sent nothing for {seconds:g} s while holding control "
                                                 f"{self._index(cid, cid)}: it was let go (the drag is a step)")
                                  for cid, who in silent])

    def _let_go(self, grabs: list[tuple[int, Hand]], lost: list[Lost]) -> None:
        with self._lock:
            ended = [(cid, who) for cid, who in grabs if self._held.get(cid) is who]
            for cid, _ in ended:
                del self._held[cid]
        self._engine(Release, [cid for cid, _ in ended])
        for cid, who in ended:
            self.timeline.end_gesture((who.id, cid))
        if ended or lost:
            self._tell(lost)

    def _engine(self, operation, control_ids) -> None:
        """The Som holds what the hands hold: a grab binds each control with a radius to the clay it takes, a release
        lets go (operations.Grab, Release: queued in order with the intents, so a drag's first move comes after its
        grab)."""
        with self.state.lock:
            ids = self.state.control_ids
            indices = tuple(ids.index(cid) for cid in control_ids if cid in ids)
            if indices:
                self.timeline.trainer.enqueue(operation(indices), intent=False)

    # -- listeners -----------------------------------------------------------------------------------------------
    def subscribe(self, listener: Callable[[list[Lost]], None]) -> None:
        """Call `listener(lost)` whenever who is here or who holds what changes (on the thread that changed it)."""
        with self._lock:
            self._listeners.append(listener)

    def unsubscribe(self, listener) -> None:
        with self._lock:
            if listener in self._listeners:
                self._listeners.remove(listener)

    def _tell(self, lost: Sequence[Lost] = ()) -> None:
        with self._lock:
            listeners = list(self._listeners)
        for listener in listeners:
            listener(list(lost))

    def _index(self, control_id: int, default=None) -> int:
        """The control's index now; ValueError when it is gone (or `default`, when given)."""
        with self.state.lock:
            if control_id in self.state.control_ids:
                return self.state.control_ids.index(control_id)
        if default is not None:
            return default
        raise ValueError(f"control {control_id} no longer exists (it was removed, or the controls were replaced)")


def refusal(what: str, index: int, holder: Hand) -> str:
    """The message a hand is refused a held control with."""
    return f"{what}: control {index} is held by {holder.name}; it is free again when they let go"


# -- a person's undo and redo ------------------------------------------------------------------------------------
def undo_own(session, hand: Hand) -> bool:
    """`hand`'s undo: its own latest step, exactly when it is the newest step, else put back on the state now as a
    step of its own (gestures.py); with no step of its own, the newest step. False when there was nothing to undo."""
    timeline = session.timeline
    step, newest = timeline.own_step(hand.id)
    if step is None or newest:
        return timeline.undo()
    change = timeline.change_of(step)
    if change.whole:
        raise ValueError(f"undo: your last step ({change.kind}) has other people's steps after it and changed which "
                         "controls there are; it cannot be taken back alone (Undo from Python takes back the whole "
                         "history)")
    ids = session.control_ids
    for cid in (*change.controls, *change.added):
        holder = session.hands.holder(cid)
        if cid in ids and holder is not None and holder is not hand:
            raise ValueError(refusal("undo", ids.index(cid), holder))
    with acting(hand.id), timeline.step("undo"):
        controls, radii = session.controls, session.control_edits.radii
        for cid, (values, radius) in change.controls.items():
            if cid in ids:
                controls[ids.index(cid)], radii[ids.index(cid)] = values, radius
        if change.controls:
            session.control_edits.replace(controls, radii)
        for cid in change.added:
            if cid in session.control_ids:
                session.control_edits.remove(session.index_of_control(cid))
        for name, value in change.parameters.items():
            if name == "metric_weights":
                session.settings.set_metric_weights(value)
            else:
                session.settings.set(name, value)
    timeline.taken_back(step)
    return True


def redo_own(session, hand: Hand) -> bool:
    """`hand`'s redo: right after its undo of an older step, that undo is taken back; else the newest undone step."""
    done = session.timeline.redo_own(hand.id)
    return session.timeline.redo() if done is None else done
