"""The app layer around the engine, by role; imports run one way: hosts -> transport -> model -> backend.

model/      the modelling session and its parts (no UI, no network): Session, Frame
transport/  what travels between a session and its views: the wire messages (declared once; the browser's side
            generated from them), frame encoding, the outbox, one view connection, who holds which control
web/        the trame web app (`somwidget serve`), its websocket hub and routes, the LAN guard
notebook/   Jupyter: show(), the ipywidgets panel, the anywidget clay view
client/     the one browser client (JavaScript): the clay view, the link, the headset page
"""

from .model import Frame, Session

__all__ = ["Frame", "Session"]
