"""The rooms of one worker (a process, a GPU): each room a Session of its own (its clay, controls, settings, undo
history and autosave folder) with a view hub for its views (web/hub.py), made on first open, parked when idle and
brought back from its folder on the next open.

A room's folder, under the studio's rooms folder (one folder every worker of a cluster reaches):

    <rooms>/<name>/room.json    its name, token, preset, when it was made and last changed (written atomically)
    <rooms>/<name>/thumb.bin    its last thumbnail for the wall (thumbs.py; written atomically)
    <rooms>/<name>/session/     its autosave (model/store.py): each completed step with the undo history, locked while
                                a process has the room

Parking (`park`, `park_idle`): a room with no view for `limits.park_after` seconds is closed: what changed since its
last save is written, its Som (GPU memory) and Session (CPU memory) go; its last thumbnail stays for the wall (and in
its folder, for the wall after a restart; a live room's is written there too, at most every THUMB_SAVE_PERIOD seconds
while it changes, so a room whose worker died shows its clay after a restart). `open` brings it back from its folder
as the autosave left it (its last completed step with its undo history; nothing trains until the next intent), as it
does after a crash or on another worker after this one died.
"""

from __future__ import annotations

import contextlib
import ctypes
import gc
import json
import logging
import shutil
import threading
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from ...backend import presets as _presets
from ...backend.device import resolve
from ...backend.session_file import write_atomic
from ..model import Session
from ..model.readback import read_folder
from ..model.store import LOCK, SessionStore, set_aside
from ..web.hub import ViewHub
from .batched import BatchedRooms
from .limits import StudioFull, StudioLimits, check_new_room, device_used_bytes, resident_bytes, room_name
from .rounds import Rounds
from .thumbs import THUMB_FILE, public_shape, read_thumb, save_thumb, shape_of, thumbnail

log = logging.getLogger(__name__)

RECORD = "room.json"
SESSION = "session"
#: Frames a second a room's views get (and its training thread aims at).
FRAME_RATE = 30.0
#: Seconds at least between two writes of a changing room's thumbnail into its folder.
THUMB_SAVE_PERIOD = 10.0


class RoomBusy(RuntimeError):
    """The room's folder is held by another live process (a worker that still has it)."""


@dataclass
class RoomRecord:
    """What room.json keeps of a room."""

    name: str
    token: str
    preset: str = "car"
    created: float = 0.0
    last_change: float = 0.0

    @classmethod
    def read(cls, folder: Path) -> RoomRecord:
        data = json.loads((folder / RECORD).read_text(encoding="utf-8"))
        record = cls(**{k: data[k] for k in ("name", "token", "preset", "created", "last_change") if k in data})
        if record.name != folder.name or not record.token:
            raise ValueError(f"{folder / RECORD}: names room {record.name!r}, expected {folder.name!r} with a token")
        return record

    def write(self, folder: Path) -> None:
        text = json.dumps(asdict(self)).encode("utf-8")
        write_atomic(folder / RECORD, lambda f: f.write(text))


class Room:
    """One room: its record, and while it is live its Session and the hub of its views."""

    def __init__(self, folder: Path, record: RoomRecord):
        self.folder = folder
        self.record = record
        self.session: Session | None = None
        self.hub: ViewHub | None = None
        self.lock = threading.RLock()  # opening and parking, one at a time
        self.last_active = time.monotonic()  # a view was there (or the room opened)
        self.notices: list[str] = []
        self._applied = 0
        self._thumb: tuple[int, int, dict, bytes] | None = None  # (generation, seq, shape, bytes), kept when parked
        self._thumb_unsaved = False  # _thumb is not in the folder yet
        self._thumb_saved = 0.0  # when it was last written there (monotonic)

    @property
    def name(self) -> str:
        return self.record.name

    @property
    def live(self) -> bool:
        return self.session is not None

    def _on_frame(self, frame) -> None:
        """Training thread: an intent handled since the last frame is a change."""
        if frame.applied != self._applied:
            self._applied = frame.applied
            self.record.last_change = time.time()

    def views(self) -> list:
        hub = self.hub
        return list(hub.clients.values()) if hub is not None else []

    def info(self) -> dict:
        """The room as the wall and /api/rooms list it."""
        session, views = self.session, self.views()
        watching = {c.connection.hand.id for c in views if getattr(c.connection, "watch", False)}
        people = []
        if session is not None:
            people = [{"name": h.name, "kind": h.kind, "colour": h.colour, "holds": list(holds)}
                      for h, holds in session.hands.present() if h.id not in watching]
        preset = session.preset if session is not None else None
        return {"name": self.name, "live": session is not None, "preset": preset.name if preset else
                self.record.preset, "title": preset.title if preset else self.record.preset,
                "nodes": int(preset.n_vertices) if preset else None, "people": people, "watchers": len(watching),
                "last_change": self.record.last_change, "created": self.record.created,
                "saves": session.autosave.writer.saves if session is not None and session.autosave else 0,
                "error": session.error if session is not None else None, "notices": list(self.notices)}

    def latest_thumb(self) -> tuple[int, int, dict, bytes] | None:
        """(generation, seq, shape, thumbnail bytes) of the room's latest frame (parked: of its last one); kept in its
        folder when it changed, at most every THUMB_SAVE_PERIOD seconds (and when it parks: `save_thumb`)."""
        session = self.session
        if session is not None:
            frame = session.frame
            if self._thumb is None or self._thumb[1] != frame.seq:
                shape = shape_of(frame.preset or session.preset)
                self._thumb = (frame.generation, frame.seq, public_shape(shape), thumbnail(frame, shape))
                self._thumb_unsaved = True
                if time.monotonic() - self._thumb_saved >= THUMB_SAVE_PERIOD:
                    self.save_thumb()
        return self._thumb

    def keep_thumb(self) -> None:
        """The room's latest thumbnail into its folder when its clay changed and THUMB_SAVE_PERIOD passed since the
        last one went there, whether or not a wall is open: a room whose worker dies without parking it shows its
        clay on the wall after a restart, as it was at most THUMB_SAVE_PERIOD seconds before."""
        if time.monotonic() - self._thumb_saved >= THUMB_SAVE_PERIOD:
            self.latest_thumb()
            self.save_thumb()

    def save_thumb(self) -> None:
        """The latest thumbnail into the room's folder (thumbs.py), unless it is there already."""
        if self._thumb is None or not self._thumb_unsaved:
            return
        try:
            save_thumb(self.folder, self._thumb)
        except OSError as exc:  # the wall shows it while this process lives; only a restart would miss it
            log.warning("studio: room %s: its thumbnail cannot be kept in %s: %s", self.name, self.folder, exc)
        self._thumb_unsaved = False
        self._thumb_saved = time.monotonic()


class Rooms:
    """The rooms of this worker (see the module's docstring). folder: the studio's rooms folder; device: where their
    Soms train ("cpu", "cuda:0", "auto"); label: this worker as messages name it."""

    def __init__(self, folder, device: str = "auto", limits: StudioLimits | None = None,
                 frame_rate: float = FRAME_RATE, label: str | None = None):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.device = resolve(device)  # "cpu" or "cuda:N": where every room of this worker trains
        self.limits = limits or StudioLimits()
        self.frame_rate = float(frame_rate)
        self.label = label or f"this worker ({device})"
        self._rooms: dict[str, Room] = {}
        self._lock = threading.Lock()
        self._closed = False
        self._kept_thumbs: dict[str, tuple[int, tuple | None]] = {}  # name -> (mtime_ns, read_thumb) of a folder
        self.batches = BatchedRooms()  # alike rooms held in one batch, stepped in one launch (batched.py)
        self.rounds = Rounds(self.batches, self.frame_rate)  # one loop steps every room (rounds.py)

    def warm(self, preset: str = "car") -> None:
        """Step a throwaway room of `preset` alone and in a batch on this worker's device, so that the kernels' modules
        are loaded before the worker takes rooms: a GPU's first launches load them, which takes seconds while eight
        workers a GPU start at once, and a first room made meanwhile would outlast the front's call."""
        som = _presets.get_preset(preset).make_som(device=self.device)
        som.step(2)
        batches = BatchedRooms()
        key = batches.key(som)
        assert key is not None  # a preset's Som of point controls is batched
        batches.hold(0, som, key)
        batches.step([(0, 2)])
        batches.forget()

    # -- the rooms --------------------------------------------------------------------------------------------
    def known(self) -> list[RoomRecord]:
        """Every room with a folder (live here, parked, or another worker's), read from the rooms folder."""
        found = []
        for entry in sorted(self.folder.iterdir()):
            if not (entry / RECORD).is_file():
                continue
            try:
                found.append(RoomRecord.read(entry))
            except (OSError, ValueError, TypeError, KeyError) as exc:
                log.warning("studio: skipping %s: %s", entry, exc)
        return found

    def get(self, name: str) -> Room | None:
        with self._lock:
            return self._rooms.get(room_name(name))

    def live(self) -> list[Room]:
        with self._lock:
            return [r for r in self._rooms.values() if r.live]

    def rooms(self) -> list[Room]:
        with self._lock:
            return list(self._rooms.values())

    def create(self, name: str, token: str, preset: str = "car") -> Room:
        """A new room of `preset` (its folder made, its session started). ValueError when the name is taken or the
        preset unknown; StudioFull past a limit."""
        name = room_name(name)
        if preset not in _presets.PRESETS:
            raise ValueError(f"unknown preset {preset!r}; known presets: {', '.join(_presets.PRESETS)}")
        folder = self.folder / name
        with self._lock:
            if name in self._rooms or (folder / RECORD).exists():
                raise ValueError(f"a room named {name!r} exists already")
        n_nodes = _presets.PRESETS[preset]().n_vertices
        check_new_room(self.limits, len(self.live()), n_nodes, self.device, self.label)
        folder.mkdir(parents=True, exist_ok=True)
        record = RoomRecord(name, token, preset, created=time.time(), last_change=time.time())
        record.write(folder)
        room = Room(folder, record)
        with room.lock:
            with self._lock:
                self._rooms[name] = room
            try:
                self._start(room, Session(preset, start=False,
                                          **self._options(SessionStore(folder / SESSION, "studio"))))
            except BaseException:
                with self._lock:
                    self._rooms.pop(name, None)
                shutil.rmtree(folder, ignore_errors=True)  # made just now: nothing of anyone's is in it
                raise
        log.info("studio: room %s made (%s) on %s", name, preset, self.label)
        return room

    def open(self, name: str) -> Room:
        """The room, live: brought back from its folder if it is parked (or another worker's that died). KeyError when
        there is no such room; StudioFull past a limit; RoomBusy while another live process holds it."""
        name = room_name(name)
        with self._lock:
            room = self._rooms.get(name)
        if room is None:
            folder = self.folder / name
            try:
                record = RoomRecord.read(folder)
            except FileNotFoundError:
                raise KeyError(name) from None
            except (OSError, ValueError, TypeError, KeyError) as exc:
                raise KeyError(f"{name}: {exc}") from None
            with self._lock:
                room = self._rooms.setdefault(name, Room(folder, record))
        with room.lock:
            room.last_active = time.monotonic()
            if not room.live:
                self._bring_back(room)
        return room

    def _options(self, store) -> dict:
        return {"device": self.device, "frame_rate": self.frame_rate, "max_vertices": self.limits.nodes,
                "origin": "studio", "_store": store}

    def _start(self, room: Room, session: Session) -> None:
        """Make `session` the room's and start it, its turns run by the worker's loop with the other rooms' (caller
        holds room.lock)."""
        session.trainer.driver = self.rounds
        session.start()
        room.session = session
        room._applied = session.frame.applied
        session.add_listener(room._on_frame, replay=False)
        room.hub = ViewHub(session)  # frames sent as they come (at most messages.MAX_FPS): none waits for a pace
        room.last_active = time.monotonic()

    def _bring_back(self, room: Room) -> None:
        """The room's session from its folder (caller holds room.lock), read and checked whole first (readback.py,
        as a restart does): read whole, it goes on saving there, nothing written until its next step; anything
        unreadable, the folder is set aside whole and what could be read comes back in a new one (a notice says)."""
        live = len(self.live())
        check_new_room(self.limits, live, 0, self.device, self.label)  # the count; its nodes were checked when made
        folder = room.folder / SESSION
        if (folder / "manifest.json").exists():
            try:
                store = SessionStore.adopt(folder)
            except OSError as exc:
                raise RoomBusy(f"room {room.name!r} cannot be opened: its folder's lock {folder / LOCK} cannot be "
                               f"taken ({exc.strerror or exc})") from None
            if store is None:
                raise RoomBusy(f"room {room.name!r} is open in another process (its folder {folder} is locked); "
                               "try again in a moment")
            reading = read_folder(folder, self.limits.nodes)
            if reading.whole:
                if self._rebuild(room, reading, store, on_disk=True):
                    return
            else:
                aside = store.set_aside()
                problems = "; ".join(dict.fromkeys(str(p) for p in reading.problems))
                if reading.current is not None:
                    _moved_to(reading, aside)
                    room.notices.append(f"part of the room's saved state cannot be read ({problems}); what could be "
                                        f"read is back, the folder as it was is kept at {aside}")
                    log.warning("studio: room %s: %s", room.name, room.notices[-1])
                    if self._rebuild(room, reading, SessionStore(folder, "studio", writable=False), on_disk=False):
                        return
                else:
                    room.notices.append(f"the room's saved state cannot be read ({problems}); it is kept at {aside} "
                                        f"and the room starts again from {room.record.preset}")
                    log.warning("studio: %s", room.notices[-1])
        elif folder.exists() and any(folder.iterdir()):  # a folder without a manifest: kept, never deleted
            set_aside(folder)
        self._start(room, Session(room.record.preset, start=False, **self._options(SessionStore(folder, "studio"))))

    def _rebuild(self, room: Room, reading, store: SessionStore, on_disk: bool) -> bool:
        """Start the room's session from what `reading` brought back into `store`; False (the folder set aside, a
        notice) when it cannot be rebuilt."""
        session = None
        try:
            session = Session(reading.current.preset, start=False, **self._options(store))
            session.timeline.bring_back(reading.current, reading.undo, reading.redo)
            if on_disk:
                store.take_over(reading.files, reading.presets, reading.current.key)
            assert session.autosave is not None  # a session given a store (_options) autosaves into it
            session.autosave.arm(on_disk=on_disk)
        except Exception as exc:  # noqa: BLE001 - the room starts afresh; the folder is kept aside unchanged
            if session is not None:
                session.close(timeout=2.0)
            kept = f"it is kept at {store.set_aside()} and " if on_disk else ""  # else set aside already
            room.notices.append(f"the room's saved state could not be brought back ({type(exc).__name__}: {exc}); "
                                f"{kept}the room starts again from {room.record.preset}")
            log.warning("studio: %s", room.notices[-1])
            return False
        self._start(room, session)
        log.info("studio: room %s brought back on %s (%d undo steps)", room.name, self.label, len(reading.undo))
        return True

    # -- parking ----------------------------------------------------------------------------------------------
    def park(self, name: str, force: bool = False) -> bool:
        """Close a live room that has no view (or, `force`, whatever it has: its views are dropped): saved, memory
        freed, its last thumbnail kept. False when it was not live or has views."""
        room = self.get(name)
        if room is None:
            return False
        with room.lock:
            session = room.session
            if session is None or (room.views() and not force):  # not live, or has views
                return False
            room.latest_thumb()  # the last picture, for the wall (kept in its folder for after a restart)
            room.save_thumb()
            hub = room.hub
            room.session = room.hub = None
        assert hub is not None  # made with the session (Rooms._start)
        hub.detach()
        for client in list(hub.clients.values()):
            client.drop(b"the room was parked")
        session.remove_listener(room._on_frame)
        session.close(timeout=10.0)
        with contextlib.suppress(OSError):
            room.record.write(room.folder)
        del session, hub
        if not self.live():
            self.batches.forget()
        release_memory()
        log.info("studio: room %s parked on %s", name, self.label)
        return True

    def park_idle(self) -> list[str]:
        """The worker's look at its rooms every few seconds: each live room's thumbnail kept in its folder when due
        (`Room.keep_thumb`), then the rooms without a view for `limits.park_after` seconds parked (none when it is
        0); their names."""
        for room in self.live():
            room.keep_thumb()
        after = self.limits.park_after
        if after <= 0:
            return []
        now, parked = time.monotonic(), []
        for room in self.live():
            if room.views():
                room.last_active = now
            elif now - room.last_active >= after and self.park(room.name):
                parked.append(room.name)
        return parked

    # -- for the front ----------------------------------------------------------------------------------------
    def thumbs(self, seen: dict) -> list[dict]:
        """The thumbnails of the rooms named in `seen` ({name: the seq the wall has, or None}) other than those it has:
        a room held here from its frame (or its last), any other from its folder (a room parked before a restart).
        Each {"name", "generation", "seq", "shape", "thumb": bytes}."""
        out = []
        for name, last in seen.items():
            try:
                name = room_name(name)
            except ValueError:
                continue
            room = self.get(name)
            kept = room.latest_thumb() if room is not None else None
            kept = kept if kept is not None else self._kept_thumb(name)
            if kept is not None and kept[1] != last:
                out.append(dict(zip(("generation", "seq", "shape", "thumb"), kept), name=name))
        return out

    def _kept_thumb(self, name: str) -> tuple | None:
        """What the room's folder keeps of its last thumbnail (read again only when the file changed)."""
        path = self.folder / name / THUMB_FILE
        try:
            mtime = path.stat().st_mtime_ns
        except OSError:
            return None
        cached = self._kept_thumbs.get(name)
        if cached is None or cached[0] != mtime:
            try:
                kept = read_thumb(path.parent)
            except (OSError, ValueError) as exc:
                log.warning("studio: room %s: its kept thumbnail is not shown: %s", name, exc)
                kept = None
            cached = self._kept_thumbs[name] = (mtime, kept)
        return cached[1]

    def listing(self) -> list[dict]:
        return [room.info() for room in self.rooms()]

    def load(self) -> dict:
        """How loaded this worker is: live rooms and their nodes, its memory, its latest rounds' durations."""
        live = self.live()
        return {"rooms": len(live), "nodes": sum(int(r.session.preset.n_vertices) for r in live if r.session),
                "limit": self.limits.rooms, "rss_mb": resident_bytes() / 2**20,
                "gpu_mb": device_used_bytes(self.device) / 2**20, "round": self.rounds.timings()}

    def close(self) -> None:
        """Close every live room (each saved; the folders stay)."""
        self._closed = True
        for room in self.live():
            self.park(room.name, force=True)
        self.rounds.stop()


def _moved_to(reading, aside: Path) -> None:
    """The steps whose weights stay on disk read them from the folder's new name (it was set aside)."""
    def moved(step):
        return replace(step, weights=aside / step.weights.name) if isinstance(step.weights, Path) else step

    reading.undo = [moved(s) for s in reading.undo]
    reading.redo = [moved(s) for s in reading.redo]


def release_memory() -> None:
    """Collect what parking let go of, and hand the freed heap back to the system (glibc)."""
    gc.collect()
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL("libc.so.6").malloc_trim(0)


__all__ = ["Room", "RoomBusy", "RoomRecord", "Rooms", "StudioFull", "FRAME_RATE"]
