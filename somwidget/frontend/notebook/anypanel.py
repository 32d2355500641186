"""The panel as an anywidget (panel.js), for hosts that draw anywidgets but not ipywidgets (marimo), and any other:
the same panel model (model/panel.py) and the same declaration of the settings (backend/schedule.py SETTINGS) as
the ipywidgets panel (panel.py), the fields laid out by the browser for widths from 320 px.

In marimo:

    import marimo as mo
    import somwidget
    view = somwidget.show("car")          # in marimo: this panel and the live view
    mo.hstack([mo.ui.anywidget(view.panel), mo.ui.anywidget(view.view)], wrap=True)

(or `view` alone as the cell's last expression: SomWidget._display_ does the same.)
"""

from __future__ import annotations

import logging
import threading
import time
from pathlib import Path
from typing import Any

import anywidget
import traitlets

from ...backend.schedule import SECTIONS
from ..model import Frame, Session
from ..model.panel import (
    ACTION_NAMES,
    ACTIONS,
    EXPORT_CHOICES,
    OFF_CLAY_HELP,
    OFF_CLAY_STYLE,
    PanelModel,
    slider_digits,
)
from .panel import PANEL_HZ, PRESET_LABELS

log = logging.getLogger(__name__)
ESM = Path(__file__).with_name("panel.js")


def declared_fields(model: PanelModel) -> list[dict]:
    """What panel.js lays out for each setting a panel sets by name: its declaration, a slider's range and step."""
    out = []
    for p in model.fields:
        low, high, step = p.slider or (p.low, p.high, 1)
        out.append({"name": p.name, "label": p.label, "short": p.short, "kind": p.kind, "widget": p.widget,
                    "section": p.section, "help": p.help, "min": low, "max": high, "step": step,
                    "digits": slider_digits(p)})
    return out


class PanelWidget(anywidget.AnyWidget):
    """The panel bound both ways to `session` (see the module's docstring); `error` shows a refused edit."""

    fields: traitlets.List[Any] = traitlets.List().tag(sync=True)
    sections = traitlets.Dict().tag(sync=True)
    values = traitlets.Dict().tag(sync=True)
    status = traitlets.Dict().tag(sync=True)
    presets: traitlets.List[Any] = traitlets.List().tag(sync=True)
    groups: traitlets.List[Any] = traitlets.List().tag(sync=True)
    features: traitlets.List[Any] = traitlets.List().tag(sync=True)
    controls: traitlets.List[Any] = traitlets.List().tag(sync=True)
    exports: traitlets.List[Any] = traitlets.List().tag(sync=True)
    actions = traitlets.Dict().tag(sync=True)  # name -> [label, help] (model/panel.py ACTIONS)
    # the gap cell's mark for a control off the clay: [style, words]
    off_clay: traitlets.List[Any] = traitlets.List().tag(sync=True)
    error = traitlets.Unicode("").tag(sync=True)

    def __init__(self, session: Session, refresh_hz: float = PANEL_HZ, auto_refresh: bool = True) -> None:
        self.session = session
        self.model = PanelModel(session)
        super().__init__(_esm=ESM.read_text(encoding="utf-8"), fields=declared_fields(self.model),
                         sections={k: list(v) for k, v in SECTIONS.items()},
                         exports=[[label, ext] for ext, label in EXPORT_CHOICES],
                         actions={a.name: [a.label, a.help] for a in ACTIONS},
                         off_clay=[OFF_CLAY_STYLE, OFF_CLAY_HELP])
        self.refresh_hz = float(refresh_hz)
        self._latest: Frame | None = None
        self._wake = threading.Event()
        self._closed = False
        self.on_msg(self._on_message)
        self.refresh()
        session.add_listener(self._on_frame, replay=False)
        self._thread = None
        if auto_refresh:
            self._thread = threading.Thread(target=self._refresh_loop, name="somwidget-anypanel", daemon=True)
            self._thread.start()

    # -- browser -> session ------------------------------------------------------------------------------------
    def _on_message(self, _widget, msg: dict, _buffers) -> None:
        """A person's edit or press; a refused one shows its message (`error`)."""
        kind = msg.get("type") if isinstance(msg, dict) else None
        m = self.model
        if kind == "set":
            error = m.set(str(msg.get("name")), msg.get("value"))
        elif kind == "metric":
            error = m.set_metric(msg.get("d"), msg.get("value"))
        elif kind == "group":
            error = m.set_group(msg.get("spec"))
        elif kind == "preset":
            error = m.attempt(self.session.load_preset, str(msg.get("name")))
        elif kind == "action" and msg.get("name") in ACTION_NAMES:
            error = m.run(msg["name"])
        elif kind == "radius":
            error = m.set_radius(msg.get("i"), msg.get("value"))
        elif kind == "position":
            error = m.set_position(msg.get("i"), msg.get("text"))
        elif kind == "export":
            error = self.download(msg.get("ext"))
        else:
            error = f"panel: unknown message {str(msg)[:80]!r}"
        self.error = error or ""
        self._wake.set()

    def download(self, ext) -> str | None:
        """Send the clay in format `ext` to the browser, which saves it under the session's name; None if sent."""
        try:
            data = self.model.export_bytes(ext)
        except (ValueError, OSError) as exc:
            return str(exc)
        self.send({"type": "download", "name": self.model.export_name(ext), "mime": "application/octet-stream"},
                  buffers=[data])
        return None

    # -- session -> browser ------------------------------------------------------------------------------------
    def _on_frame(self, frame: Frame) -> None:
        self._latest = frame
        self._wake.set()

    def _refresh_loop(self) -> None:
        while not self._closed:
            self._wake.wait(1.0)
            self._wake.clear()
            if self._closed:
                break
            try:
                self.refresh()
            except Exception:  # a failed refresh must not end the loop
                log.exception("panel refresh failed")
            time.sleep(1.0 / self.refresh_hz)

    def refresh(self) -> None:
        """Bring the traits in line with the session and its latest frame."""
        session, m = self.session, self.model
        frame = self._latest or session.frame
        if frame.generation != session.generation:
            frame = session.frame
        status = m.status(frame)
        status.update(title=session.preset.title, preset=session.preset.name)
        with self.hold_sync():
            self.values = m.values()
            self.status = status
            self.presets = [list(o) for o in m.preset_options(PRESET_LABELS)]
            self.groups = [list(o) for o in m.group_choices()]
            self.features = m.feature_rows()
            self.controls = m.control_rows(frame)

    def close(self) -> None:
        """Stop following the session (it goes on) and close the widget."""
        self._closed = True
        self._wake.set()
        self.session.remove_listener(self._on_frame)
        super().close()


__all__ = ["PanelWidget", "declared_fields"]
