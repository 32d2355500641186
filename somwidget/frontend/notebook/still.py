"""The still: a small picture of the clay that a notebook output keeps next to the live view, so that the saved file
shows the clay wherever it is read: reopened without its kernel, as nbconvert's HTML, on GitHub or nbviewer, in a
host without the widget extension.

How a host picks what to draw: a notebook output is a bundle of MIME types, and JupyterLab (Notebook 7 and Voila
use the same output area) draws the one of highest rank that it may. The widget's view
(application/vnd.jupyter.widget-view+json) ranks first, but its renderer is not "safe": in a notebook that is not
trusted (a file from someone else) the host draws the best safe type instead, and where the widget's model is gone
(a saved notebook reopened: the kernel that held it has gone) the widget renderer writes "Error displaying widget:
model not found" rather than falling back to another type of the same bundle. nbconvert skips the widget's type
when the file holds no widget state (the default), GitHub and nbviewer draw images and HTML.

So `show()` leaves two outputs (SomWidget._ipython_display_): the live view (the widget's type and a line of text)
and the still (this module): its HTML is the picture plus a style sheet for JupyterLab's output area that hides the
still while a live view stands before it and, once the widget is gone, the widget's error in its place (a trusted
notebook runs its HTML unchanged); its image/png is the same picture for a reader that draws images only. The picture
is the view's own (the browser sends one once the view is still, ClayWidget.picture) made small here (at most
STILL_SIZE, a palette of STILL_COLOURS colours, under STILL_BYTES), and each new one replaces the still in place
(update_display, by the display's id) so the file keeps the clay as it was last seen. Before a browser has drawn one
(a notebook run by nbclient, no browser) the picture is rendered off screen (model/picture.py, pyvista).
"""

from __future__ import annotations

import base64
import io
import logging
from typing import Any

log = logging.getLogger(__name__)

#: The still's largest size in pixels (width, height): a thumbnail beside the code, not a second view.
STILL_SIZE = (480, 320)
#: Colours in the still's palette (the clay's shading needs few; fewer make a smaller file).
STILL_COLOURS = 192
#: The most bytes one still's PNG may take: twice in the file (HTML and image/png) and in base64, under 200 KB.
STILL_BYTES = 70_000
#: The widget output's text, where a host shows text in its place (no widget manager, an untrusted notebook).
LIVE_TEXT = "somwidget: the live clay view (run the cell to model); the still below shows the clay as last seen"

#: JupyterLab's output area (also Notebook 7's and Voila's), where the still's output comes right after the widget's:
#: the still is hidden while a live view stands in the output before it; the widget's output is hidden while no live
#: view stands in the output area (loading, or the widget manager's "Error displaying widget: model not found" once
#: the model is gone). Other hosts ignore these rules and show both.
STILL_STYLE = """<style>
.jp-OutputArea-child:has(.somview) + .jp-OutputArea-child:has(.somwidget-still) { display: none; }
.jp-OutputArea:not(:has(.somview)) > .jp-OutputArea-child:has(+ .jp-OutputArea-child .somwidget-still) {
  display: none;
}
</style>"""


#: The still before there is a picture of the clay (the view's first one replaces it).
WAITING = {"text/html": f'{STILL_STYLE}<small class="somwidget-still">the clay\'s still comes once the view has drawn'
                        "</small>", "text/plain": "the clay's still comes once the view has drawn (somwidget)"}


def small_png(png: bytes, size: tuple[int, int] = STILL_SIZE, budget: int = STILL_BYTES) -> tuple[bytes, tuple]:
    """(a PNG of at most `size` pixels and `budget` bytes, its (width, height)) from a PNG of the clay: scaled down,
    its colours reduced to a palette (STILL_COLOURS, fewer and smaller again until it fits)."""
    from PIL import Image

    image = Image.open(io.BytesIO(png)).convert("RGB")
    image.thumbnail(size, Image.Resampling.LANCZOS)
    colours = STILL_COLOURS
    while True:
        small = image.quantize(colours, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
        out = io.BytesIO()
        small.save(out, format="PNG", optimize=True)
        data = out.getvalue()
        if len(data) <= budget or image.width < 120:
            return data, image.size
        if colours > 32:
            colours //= 2
        else:
            image = image.resize((image.width * 3 // 4, image.height * 3 // 4), Image.Resampling.LANCZOS)


def still_bundle(png: bytes) -> tuple[dict, dict]:
    """(data, metadata) of the still's output from a PNG of the clay (any size)."""
    data, (width, height) = small_png(png)
    b64 = base64.b64encode(data).decode("ascii")
    html = (f'{STILL_STYLE}<img class="somwidget-still" alt="the clay, as last seen" width="{width}" '
            f'height="{height}" src="data:image/png;base64,{b64}">')
    return ({"text/html": html, "image/png": b64, "text/plain": "the clay, as last seen (somwidget)"},
            {"image/png": {"width": width, "height": height}})


class Stills:
    """The stills of one widget's outputs: `show(png)` leaves a new one (IPython's display, with an id of its own),
    `update(png)` replaces every one shown with the new picture."""

    def __init__(self) -> None:
        self.handles: list[Any] = []  # IPython's DisplayHandle of each still shown
        self.updates = 0  # stills replaced (for tests)

    def show(self, png: bytes | None) -> None:
        """Leave a still of `png`; without one (nothing renders off screen here), a line that the view's first
        picture replaces."""
        from IPython.display import display

        data, metadata = still_bundle(png) if png is not None else (WAITING, {})
        handle = display(data, metadata=metadata, raw=True, display_id=True)
        if handle is not None:
            self.handles.append(handle)

    def update(self, png: bytes | None) -> None:
        if png is None or not self.handles:
            return
        try:
            data, metadata = still_bundle(png)
        except Exception:  # a picture Pillow cannot read: keep the still there is
            log.debug("the view's picture is not a PNG Pillow reads", exc_info=True)
            return
        for handle in self.handles:
            handle.update(data, metadata=metadata, raw=True)
        self.updates += 1


__all__ = ["Stills", "still_bundle", "small_png", "LIVE_TEXT", "STILL_STYLE"]
