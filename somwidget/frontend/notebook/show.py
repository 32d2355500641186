"""somwidget inside Jupyter: `show()` puts the panel (panel.py) beside the live 3-D clay view (widget.py), both bound
to one Session, and returns them as a `SomWidget`.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")  # the saved notebook's picture

import ipywidgets as widgets  # noqa: E402

from ...backend import presets as _presets  # noqa: E402
from ...backend.presets import Preset  # noqa: E402
from ..client import view_module  # noqa: E402
from ..model import Session  # noqa: E402
from .panel import Panel  # noqa: E402
from .widget import ClayWidget  # noqa: E402

log = logging.getLogger(__name__)


class SomWidget(widgets.HBox):
    """The panel and the live view side by side: `session`, `panel`, `view` (a ClayWidget; None without one).

    A saved notebook reads without a kernel: the output keeps a picture of the clay (image/png next to the widget)
    as the view last showed it, or as it was when shown; the widget state, where the notebook saves it, keeps the
    view's latest picture (ClayWidget.picture), which the view shows until frames come again."""

    def __init__(self, session: Session, panel: Panel, view: ClayWidget | None = None, owns_session: bool = False):
        self.session = session
        self.panel = panel
        self.view = view
        self.owns_session = owns_session
        children = [panel] if view is None else [panel, view]
        if view is not None:
            view.layout = widgets.Layout(flex="1 1 auto", min_width="360px")
        super().__init__(children, layout=widgets.Layout(width="100%", align_items="flex-start"))
        self.add_class("somwidget-show")  # the view's module keeps the keys typed in here from Jupyter's shortcuts

    def _repr_mimebundle_(self, **kwargs):
        bundle = super()._repr_mimebundle_(**kwargs)
        if self.view is not None and isinstance(bundle, dict):
            try:
                bundle["image/png"] = self.view.picture_png() or picture_png(self.session)
            except Exception:  # no off-screen rendering here: the live view is all there is
                log.debug("no picture for the saved notebook", exc_info=True)
        return bundle

    def close(self) -> None:
        """Close the widgets, and the session when show() made it."""
        self.panel.close()
        if self.view is not None:
            self.view.close()
        if self.owns_session:
            self.session.close()
        super().close()


def picture_png(session: Session, size=(640, 420)) -> bytes:
    """The session's latest frame as a PNG (pyvista, off screen)."""
    from ..model.picture import png_bytes, render

    return png_bytes(render(session, size=size))


def _session_of(what, device, paused: bool) -> tuple[Session, bool]:
    """(session, made_here) from a Session, a SomWidget, a Preset, a preset name or a mesh path."""
    if isinstance(what, Session):
        return what, False
    if isinstance(what, SomWidget):
        return what.session, False
    if what is None:
        what = "car"
    if isinstance(what, (str, Path)) and str(what) not in _presets.PRESETS:
        p = Path(what)
        if not p.is_file():
            raise ValueError(f"{what!r} is neither a preset ({', '.join(_presets.PRESETS)}) nor a mesh file")
        session = Session("car", device=device, start=False, paused=paused)
        try:
            session.load_mesh(p)
        except Exception:
            session.close()
            raise
        session.start()
        return session, True
    if isinstance(what, (str, Preset)):
        return Session(str(what) if isinstance(what, Path) else what, device=device, paused=paused), True
    raise ValueError(f"show: expected a preset name, a Preset, a mesh path or a Session, got {type(what).__name__}")


_DEVICES_SAID: set[str] = set()


def _say_device(session: Session) -> None:
    """Say once per kernel and device, in plain words, where the map trains."""
    from ...backend import device as _device

    where = session.training_device
    if where not in _DEVICES_SAID:
        _DEVICES_SAID.add(where)
        print(f"somwidget: training on {_device.describe(where)}")


def show(what="car", *, device: str | None = "auto", paused: bool = False, view: bool = True,
         height: int = 520) -> SomWidget:
    """An interactive SOM in a notebook cell: the panel beside the live, draggable 3-D view of one Session.

    what:     a preset name ("car", "space-grid", "lines", ...), a Preset, a mesh file path (OBJ, PLY, STL, OFF,
              GLB), an existing Session (its other views, e.g. the web app, stay in step), or a SomWidget
    device:   where a new session trains: "auto" (the GPU when there is one), "cpu", "cuda:N"
    paused:   a new session starts paused (press Train)
    view:     False: the panel alone
    height:   of the view in pixels

    Returns the widget (an ipywidgets HBox: put it last in the cell, or `display()` it); `.session` is the
    Session to script (`move_control`, `set_iterations`, `wait_idle`, `export_mesh`...), `.close()` closes it.
    The view draws in the browser from frames the kernel sends over the widget's comm: no server, no port.
    """
    if view:
        view_module()  # ClientNotBuilt (what to run) before a session is made, where the client is not built
    session, owned = _session_of(what, device, paused)
    _say_device(session)
    try:
        panel = Panel(session)
        clay = ClayWidget(session, height=height) if view else None
    except Exception:
        if owned:
            session.close()
        raise
    return SomWidget(session, panel, clay, owns_session=owned)


__all__ = ["SomWidget", "show", "picture_png"]
