"""somwidget in Jupyter: `show()` puts the ipywidgets panel beside the live clay view (an anywidget) of a Session."""

from .anypanel import PanelWidget
from .panel import Panel
from .show import SomWidget, picture_png, show
from .widget import ClayWidget

__all__ = ["Panel", "PanelWidget", "SomWidget", "ClayWidget", "show", "picture_png"]
