"""The web panel's state: the session's panel model (model/panel.py) bound to trame's state, both ways. Frames
refresh the panel's numbers a few times a second (a task on the server's event loop, `pump`); the fields follow
the preset, the history and parameters set elsewhere; the page's triggers for parameters, controls, the run and
the variants land here and their refusals show at their fields and in the panel's alert.
"""

from __future__ import annotations

import asyncio
import base64
import logging
import threading
import time

from ..model import Frame, Session
from ..model.files import export_stem
from ..model.panel import PanelModel, fmt
from ..model.picture import png_bytes
from ..model.settings import BY_NAME
from .state_guard import state_key

log = logging.getLogger(__name__)

#: Panel numbers (iteration, gaps, cycle time) refresh at most this often per second.
PANEL_HZ = 8

#: The panel's notices (news, saved sessions set aside, a recovered session; not errors, which stay until closed)
#: go away by themselves this many seconds after a page first showed them.
NOTICE_SECONDS = 8.0
NOTICES = ("info_message", "notice_message", "recovered_message")


class PanelState:
    """One session's panel model in one trame server's state (see the module's docstring)."""

    def __init__(self, session: Session, state) -> None:
        self.session = session
        self._notices_shown: dict[str, tuple[str, float]] = {}  # a notice's text and when a page first showed it
        self.panel = PanelModel(session)
        self.state = state
        self._latest: Frame | None = None
        self._latest_lock = threading.Lock()
        self._generation_seen = session.frame.generation
        self._history_seen = session.frame.history
        self._params_seen = session.parameters
        self._notices_seen = session.settings.notices
        self._values_synced: dict = {}
        self._last_panel = 0.0
        self._panel_seq = -1
        session.add_listener(self._on_frame)

    def close(self) -> None:
        self.session.remove_listener(self._on_frame)

    # -- session -> panel ----------------------------------------------------------------------------------------
    def _on_frame(self, frame: Frame) -> None:
        """Training thread: keep only the latest frame; the pump shows its numbers."""
        with self._latest_lock:
            self._latest = frame

    async def pump(self) -> None:
        while True:
            try:
                self._pump_once()
            except Exception:
                log.exception("panel pump failed")
            await asyncio.sleep(1.0 / (2 * PANEL_HZ))

    def _pump_once(self) -> None:
        failed = self.session.save_error or ""
        if failed != self.state.save_error:  # a save failed or works again: at once, not with the next numbers
            with self.state:
                self.state.save_error = failed
        self._show_notice()
        self._expire_notices()
        with self._latest_lock:
            frame = self._latest
        if frame is None:
            return
        params = self.session.parameters
        if frame.generation != self._generation_seen:  # a new preset (from any view): every field
            self._generation_seen, self._history_seen, self._params_seen = frame.generation, frame.history, params
            with self.state:
                self.sync_fields(force=True)
        elif frame.history != self._history_seen or params != self._params_seen:
            # an undo, a redo, a new step or a parameter set elsewhere (a repeat within PARAMETER_STEP_SECONDS joins
            # its step, so the history alone does not tell): the fields whose values changed follow
            self._history_seen, self._params_seen = frame.history, params
            with self.state:
                self.sync_fields()
        now = time.monotonic()
        if now - self._last_panel > 1 / PANEL_HZ and (frame.seq != self._panel_seq or now - self._last_panel > 1.0):
            self.show_frame(frame)
            self._panel_seq = frame.seq
            self._last_panel = now

    def sync_fields(self, force: bool = False) -> None:
        """Panel fields that change with the preset or a parameter intent (not every frame). A parameter's field
        is written only when its value changed since the last sync (or with `force`): a field someone is typing in
        is not reset by another view's step."""
        s, sess = self.state, self.session
        values = self.panel.values()
        last = {} if force else self._values_synced
        s.preset_name = sess.preset.name
        s.preset_title = sess.preset.title
        s.preset_description = sess.preset.description
        s.export_stem = export_stem(sess.preset.name)  # downloads: "<session>-<day>-<hhmm>" (layout.py, STAMP)
        for f in self.panel.fields:
            if force or values[f.name] != last.get(f.name):
                s[state_key(f.name)] = values[f.name]
        s.group_items = [{"title": label, "value": spec} for label, spec in self.panel.group_choices()]
        s.param_group = values["group"]
        self._values_synced = values
        s.paused = sess.paused
        s.features_ui = [dict(row, weight=fmt(row["weight"], 6)) for row in self.panel.feature_rows()]
        s.has_colour = sess.layout.colour_space != "none"
        s.feature_names = self.panel.feature_names()
        s.param_errors = {}

    def _show_notice(self) -> None:
        """What a symmetry change or a revolve did to the controls (from any view or script), in the panel's news."""
        settings = self.session.settings
        if settings.notices != self._notices_seen:
            self._notices_seen = settings.notices
            with self.state:
                self.state.info_message = settings.notice

    def notice_shown(self, name: str, text: str) -> None:
        """A page shows notice `name` with `text` now (layout.py, `_shown`): its NOTICE_SECONDS start, unless a page
        showed that text already."""
        shown = self._notices_shown.get(name)
        if name in NOTICES and text and text == self.state[name] and (shown is None or shown[0] != text):
            self._notices_shown[name] = (text, time.monotonic())

    def _expire_notices(self) -> None:
        """Each notice is cleared NOTICE_SECONDS after a page first showed it (`notice_shown`; a new text starts
        again), so a person sees it that long however late the page drew it."""
        now = time.monotonic()
        for name in NOTICES:
            text, shown = self.state[name], self._notices_shown.get(name)
            if not text or (shown is not None and shown[0] != text):
                self._notices_shown.pop(name, None)
            elif shown is not None and now - shown[1] >= NOTICE_SECONDS:
                self._notices_shown.pop(name)
                with self.state:
                    self.state[name] = ""

    def show_frame(self, frame: Frame) -> None:
        with self.state as s:
            s.controls_ui = self.panel.control_rows(frame)
            s.all_radii = self.panel.common_radius(frame)
            s.stats = self.panel.status(frame)
            s.paused = frame.paused
            if self.session.error and not s.error_message:
                s.error_message = self.session.error

    def error(self, message: str) -> None:
        log.info("refused: %s", message)
        self.state.error_message = message
        self.state.flush()

    def _show(self, error: str | None) -> bool:
        """A panel model's answer: its message in the panel, or the last one cleared. True when it took it."""
        if error is not None:
            self.error(error)
        return error is None

    def _refused(self, fields: str, key: str, error: str) -> None:
        """A refused edit: its message in the panel's alert and at its field (`key` of param_errors), and the
        fields of `fields` (a parameter, "metric_weights" or "radius") drawn anew with the values in effect: the
        page binds them one way, keyed by field_revs (layout.py), so nothing refused stays in a field, nor comes
        back with a reload (the state only ever holds the session's values)."""
        log.info("refused: %s", error)
        s = self.state
        revs = dict(s.field_revs or {})
        revs[fields] = revs.get(fields, 0) + 1
        with self.state:
            s.error_message = error
            s.param_errors = {**(s.param_errors or {}), key: error}
            s.field_revs = revs

    # -- triggers ------------------------------------------------------------------------------------------------
    def set_param(self, name, value) -> None:
        error = self.panel.set(name, value)
        if error is None:
            with self.state:
                self.state.error_message = ""
                self.sync_fields()
            self._show_notice()
        else:
            field = name if isinstance(name, str) and name in BY_NAME else "other"
            self._refused(field, field, error)

    def set_metric(self, dim, value) -> None:
        error = self.panel.set_metric(dim, value)  # the session checks dim: no truncation here
        if error is None:
            with self.state:
                self.state.error_message = ""
                self.sync_fields()
        else:
            key = f"metric_weights_{dim}" if isinstance(dim, int) and not isinstance(dim, bool) else "metric_weights"
            self._refused("metric_weights", key, error)

    def set_colour(self, index, colour) -> None:
        self._show(self.panel.attempt(self.session.set_control_colour, index, colour))

    def set_radius(self, index, value) -> None:
        error = self.panel.set_radius(index, value)
        if error is None:
            self.state.error_message = ""
        else:
            self._refused("radius", "radius", error)

    def set_position(self, index, text) -> None:
        """A position typed in the controls table; refused, the row shows the position in effect again."""
        self._control_typed(self.panel.set_position(index, text), "position")

    def set_features(self, index, text) -> None:
        self._control_typed(self.panel.set_features(index, text), "features")

    def _control_typed(self, error: str | None, key: str) -> None:
        if error is None:
            self.state.error_message = ""
        else:
            self._refused("radius", key, error)  # "radius" draws the whole control row anew (layout.py)

    def set_group(self, spec) -> None:
        """A symmetry group chosen in the panel (what it did to the controls in the panel's news); refused, the field
        goes back to the group in effect."""
        error = self.panel.set_group(spec)
        self._show(error)
        with self.state:
            self.sync_fields()
        self._show_notice()

    def add_control(self) -> None:
        self._show(self.panel.attempt(self.session.add_control))

    def remove_control(self, index) -> None:
        self._show(self.panel.attempt(self.session.remove_control, index))  # "0" or 1.9 refused there

    def toggle_training(self) -> None:
        self._show(self.panel.run("toggle_training"))
        self.state.paused = self.session.paused

    def reset(self) -> None:
        self._show(self.panel.run("reset"))

    def undo(self) -> None:
        self._travel("undo")

    def redo(self) -> None:
        self._travel("redo")

    def _travel(self, action: str) -> None:
        self._show(self.panel.run(action))
        with self.state:
            self.sync_fields()
            self.show_frame(self.session.frame)

    async def sweep_variants(self) -> None:
        """Train the Variants section's design variants of the current design (a local restart each, batched on the
        session's device) and show them as a gallery of thumbnails."""
        s = self.state
        vary = [name for name in (s.variants_vary or []) if name in self.panel.varied]
        loop = asyncio.get_running_loop()

        def progress(done, total) -> None:
            loop.call_soon_threadsafe(self._set_variants_progress, 100.0 * done / max(1, total))

        def run():
            variants, thumbs = self.panel.sweep(s.variants_n, s.variants_jitter, vary, progress)
            return variants, ["data:image/png;base64," + base64.b64encode(png_bytes(t)).decode("ascii")
                              for t in thumbs]

        with self.state:
            s.busy = True
            s.variants_progress = 0
        try:
            variants, thumbs = await loop.run_in_executor(None, run)
        except (ValueError, TypeError, RuntimeError) as exc:
            self.error(f"variants: {exc}")
            return
        finally:
            with self.state:
                s.busy = False
        with self.state:
            s.variants_gallery = [{"i": i, "src": thumbs[i], "title": self.panel.caption(i, vary)}
                                  for i in range(len(variants))]
            s.variants_progress = 100

    def _set_variants_progress(self, value: float) -> None:
        with self.state:
            self.state.variants_progress = value

    def pick_variant(self, i) -> None:
        """Make gallery variant i the session's current state (one undo step)."""
        self._show(self.panel.pick(i))
