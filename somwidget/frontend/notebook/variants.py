"""The notebook panel's Variants section: many designs at once from the current one (the panel model's sweep), a
gallery of thumbnails, and a button under each to go on from it (one undo step)."""

from __future__ import annotations

import html as _html

import ipywidgets as widgets

from ..model.panel import PanelModel
from ..model.picture import png_bytes
from ..model.variants import VARIANTS_HELP

#: Text blocks: the notebook's default line height spreads small print apart.
_BLOCK = '<div style="line-height:1.35; white-space:normal">{}</div>'


class VariantsSection(widgets.VBox):
    """The panel's Variants section: how many, how much jitter, which schedule parameters to vary; Sweep trains them
    from the session's current shape (somwidget.sweep) and shows a gallery; a thumbnail's Use button makes that
    variant the session's state (one undo step, through `intent`)."""

    def __init__(self, model: PanelModel, intent) -> None:
        self.model = model
        self._intent = intent
        style = {"description_width": "initial"}
        fluid = dict(width="auto", min_width="0", max_width="100%")
        self.count = widgets.BoundedIntText(value=12, min=1, max=model.max_variants, description="how many",
                                            style=style, layout=widgets.Layout(flex="1 1 140px", **fluid))
        self.jitter = widgets.BoundedFloatText(value=0.05, min=0.0, max=1.0, step=0.01, description="jitter",
                                               style=style, layout=widgets.Layout(flex="1 1 120px", **fluid),
                                               tooltip="each control moves by up to this share of the model's size")
        self.vary = widgets.SelectMultiple(options=list(model.varied), value=(), description="vary",
                                           rows=len(model.varied), style=style,
                                           layout=widgets.Layout(flex="1 1 100%", **fluid))
        self.sweep_button = widgets.Button(description="Sweep", icon="th", tooltip=VARIANTS_HELP,
                                           layout=widgets.Layout(width="auto", min_width="fit-content"))
        self.progress = widgets.IntProgress(min=0, max=1, value=0, layout=widgets.Layout(flex="1 1 120px", **fluid))
        width = f"{model.thumbnail[0]}px"
        self.gallery = widgets.GridBox(layout=widgets.Layout(
            grid_template_columns=f"repeat(auto-fill, minmax(min({width}, 100%), {width}))", grid_gap="4px",
            width="100%"))
        wrap = widgets.Layout(flex_flow="row wrap", align_items="center", width="100%")
        self.sweep_button.on_click(lambda _b: self.sweep())
        super().__init__([
            widgets.HTML(_BLOCK.format(f'<b title="{_html.escape(VARIANTS_HELP)}">Variants</b> <small>(many '
                                       'designs at once; pick one to go on from it)</small>'),
                         layout=widgets.Layout(**fluid)),
            widgets.HBox([self.count, self.jitter], layout=wrap), self.vary,
            widgets.HBox([self.sweep_button, self.progress], layout=wrap), self.gallery,
        ], layout=widgets.Layout(width="100%"))

    @property
    def result(self):
        """The latest sweep's Variants (None before the first)."""
        return self.model.variants

    def sweep(self) -> bool:
        """Train the variants (in this thread) and show them; False (the message in the panel) if refused."""
        def run() -> None:
            self.progress.max, self.progress.value = int(self.count.value), 0
            variants, thumbs = self.model.sweep(self.count.value, float(self.jitter.value), list(self.vary.value),
                                                progress=lambda done, total: setattr(self.progress, "value", done))
            self._show(variants, thumbs)

        self.sweep_button.disabled = True
        try:
            return self._intent(run)
        finally:
            self.sweep_button.disabled = False

    def _show(self, variants, thumbs) -> None:
        cells = []
        width, height = (f"{x}px" for x in self.model.thumbnail)
        for i, image in enumerate(thumbs):
            picture = widgets.Image(value=png_bytes(image), format="png",
                                    layout=widgets.Layout(width=width, height=height))
            use = widgets.Button(description=f"use #{i}", layout=widgets.Layout(width=width, height="24px"),
                                 tooltip=self.model.caption(i))
            use.on_click(lambda _b, i=i: self.pick(i))
            cells.append(widgets.VBox([picture, use]))
        for old in self.gallery.children:
            old.close()
        self.gallery.children = cells

    def pick(self, i: int) -> bool:
        """Make variant i of the latest sweep the session's state (one undo step)."""
        def apply():
            error = self.model.pick(i)
            if error is not None:
                raise ValueError(error)

        return self._intent(apply)

    def close(self) -> None:
        for w in [*self.gallery.children, *self.children]:
            w.close()
        super().close()
