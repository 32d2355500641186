"""somwidget inside Jupyter: `show()` puts the panel (panel.py) beside the live 3-D clay view (widget.py), both bound
to one Session, and returns them as a `SomWidget`.
"""

from __future__ import annotations

import logging
import os
import threading
from pathlib import Path

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")  # the saved notebook's picture

import ipywidgets as widgets  # noqa: E402

from ...backend import presets as _presets  # noqa: E402
from ...backend.presets import Preset  # noqa: E402
from ..client import view_module  # noqa: E402
from ..model import Session  # noqa: E402
from .panel import Panel  # noqa: E402
from .still import LIVE_TEXT, Stills  # noqa: E402
from .widget import ClayWidget  # noqa: E402

log = logging.getLogger(__name__)
#: How long a still shown while the map trains waits for it to settle before it is drawn again (seconds).
STILL_WAIT_S = 300.0


class SomWidget(widgets.HBox):
    """The panel and the live view side by side: `session`, `panel`, `view` (a ClayWidget; None without one).

    A saved notebook reads without a kernel: displayed, the widget leaves the live view and, beside it, a still of the
    clay (still.py) that follows the view's latest picture, so the file shows the clay as last seen wherever it is
    read; the widget state, where the notebook saves it, keeps that picture too (ClayWidget.picture), which the view
    shows until frames come again."""

    def __init__(self, session: Session, panel, view: ClayWidget | None = None, owns_session: bool = False) -> None:
        self.session = session
        self.panel = panel
        self.view = view
        self.owns_session = owns_session
        children = [panel] if view is None else [panel, view]
        if view is not None:
            view.layout = widgets.Layout(flex="1 1 360px", min_width="280px", max_width="100%")
        super().__init__(children, layout=widgets.Layout(width="100%", align_items="flex-start",
                                                         flex_flow="row wrap"))
        self.add_class("somwidget-show")  # the view's module keeps the keys typed in here from Jupyter's shortcuts
        self.stills = Stills()
        if view is not None:
            view.observe(lambda _change: self.stills.update(view.picture_png()), names="picture")

    def _repr_mimebundle_(self, **kwargs):
        """The live view's output: the widget, and a line of text where a host cannot draw it."""
        bundle = super()._repr_mimebundle_(**kwargs)
        if isinstance(bundle, dict):
            bundle["text/plain"] = LIVE_TEXT
        return bundle

    def _ipython_display_(self) -> None:
        """In a notebook: the live view's output, then the still of the clay (still.py) beside it."""
        from IPython.display import display

        display(self._repr_mimebundle_(), raw=True)
        if self.view is not None:
            training = self.session.frame.running
            self.stills.show(self.still_png())
            if training:  # no browser may draw (a run by nbclient): the settled clay's still
                threading.Thread(target=self._still_once_settled, name="somwidget-still", daemon=True).start()

    def _still_once_settled(self) -> None:
        """Replace the stills by the settled clay, rendered off screen, unless a view's picture came first."""
        seen = self.stills.updates
        if self.session.wait_idle(STILL_WAIT_S) and self.stills.updates == seen and self.view is not None \
                and self.view.comm is not None:
            self.stills.update(self.still_png())

    def _display_(self):
        """In marimo: the panel and the view side by side (each through mo.ui.anywidget), wrapping when narrow."""
        import marimo as mo

        items = [mo.ui.anywidget(w) for w in (self.panel, self.view) if w is not None]
        return mo.hstack(items, wrap=True, align="start", justify="start")

    def still_png(self) -> bytes | None:
        """The picture a new still shows: the view's latest, else one rendered off screen (None where neither)."""
        if self.view is None:  # (shown with a view only)
            return None
        try:
            return self.view.picture_png() or picture_png(self.session)
        except Exception:  # no off-screen rendering here: the view's first picture fills the still in
            log.debug("no picture for the saved notebook", exc_info=True)
            return None

    def close(self) -> None:
        """Close the widgets, and the session when show() made it: its memory goes back to the system (a kernel
        left running after its view has gone keeps none of it)."""
        self.panel.close()
        if self.view is not None:
            self.view.close()
        super().close()
        if self.owns_session and self.session is not None:
            self.session.close()
            self.session = None  # type: ignore[assignment]  # closed: the arrays go with the last reference
            give_back_memory()


def give_back_memory() -> None:
    """Collect what is unreachable and hand the freed heap back to the system (glibc keeps freed memory of a size
    it has just freed for reuse: a closed session's hundreds of MB would stay counted against the kernel)."""
    import ctypes
    import gc
    import sys

    gc.collect()
    if sys.platform.startswith("linux"):
        try:
            ctypes.CDLL("libc.so.6").malloc_trim(0)
        except (OSError, AttributeError):  # another C library: it keeps its own ways
            pass


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


def in_marimo() -> bool:
    """True inside a marimo notebook (its cells draw anywidgets, not ipywidgets)."""
    import sys

    if "marimo" not in sys.modules:
        return False
    try:
        return bool(sys.modules["marimo"].running_in_notebook())
    except Exception:  # an older marimo, or marimo imported outside a notebook
        return False


def show(what="car", *, device: str | None = "auto", paused: bool = False, view: bool = True,
         height: int = 520, panel: str = "auto") -> SomWidget:
    """An interactive SOM in a notebook cell: the panel beside the live, draggable 3-D view of one Session.

    what:     a preset name ("car", "space-grid", "lines", ...), a Preset, a mesh file path (OBJ, PLY, STL, OFF,
              GLB), an existing Session (its other views, e.g. the web app, stay in step), or a SomWidget
    device:   where a new session trains: "auto" (the GPU when there is one), "cpu", "cuda:N"
    paused:   a new session starts paused (press Train)
    view:     False: the panel alone
    height:   of the view in pixels
    panel:    "ipywidgets" (Jupyter, Voila, VS Code, Colab), "anywidget" (anypanel.py: any host that draws
              anywidgets, marimo among them) or "auto": the anywidget panel inside marimo, else ipywidgets

    Returns the widget (an ipywidgets HBox: put it last in the cell, or `display()` it); `.session` is the
    Session to script (`move_control`, `set_iterations`, `wait_idle`, `export_mesh`...), `.close()` closes it.
    The view draws in the browser from frames the kernel sends over the widget's comm: no server, no port.
    """
    if panel not in ("auto", "ipywidgets", "anywidget"):
        raise ValueError(f"show: panel must be 'auto', 'ipywidgets' or 'anywidget', got {panel!r}")
    if view:
        view_module()  # ClientNotBuilt (what to run) before a session is made, where the client is not built
    session, owned = _session_of(what, device, paused)
    _say_device(session)
    try:
        if panel == "anywidget" or (panel == "auto" and in_marimo()):
            from .anypanel import PanelWidget

            panel = PanelWidget(session)
        else:
            panel = Panel(session)
        clay = ClayWidget(session, height=height) if view else None
    except Exception:
        if owned:
            session.close()
        raise
    return SomWidget(session, panel, clay, owns_session=owned)


__all__ = ["SomWidget", "show", "picture_png"]
