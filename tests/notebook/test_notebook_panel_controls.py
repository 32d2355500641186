"""The notebook panel's controls (issue 34, item 4), its widgets set as a person sets them: the table and the control
chooser numbered by the controls' stable ids (as the view numbers them), a stroke one row, "all radii" following a
preset switch, what a symmetry change did to the controls in the panel's message line, the open presets in its
menu."""

from __future__ import annotations

import re

import pytest

pytest.importorskip("ipywidgets")

from somwidget.backend.presets import get_preset  # noqa: E402
from somwidget.frontend.model import Session  # noqa: E402
from somwidget.frontend.notebook import Panel  # noqa: E402


@pytest.fixture
def panel():
    session = Session("sphere", device="cpu", autosave=False)
    p = Panel(session, auto_refresh=False)
    yield p
    p.close()
    session.close()


def numbers(panel) -> list[str]:
    return re.findall(r"<tr><td[^>]*>(\d+)~?</td>", panel.controls_html.value)


def test_controls_are_numbered_by_their_ids_and_a_stroke_is_one_row(panel):
    session = panel.session
    session.remove_control(1)  # as another view's Delete does
    assert session.wait_applied(30)
    panel.refresh()
    assert numbers(panel) == ["0", "2", "3", "4", "5"]
    assert [label for label, _ in panel.radius_of.options] == ["0", "2", "3", "4", "5"]
    first = session.add_stroke([[0.9, -0.3, 0.3], [0.95, 0.0, 0.35], [0.9, 0.3, 0.3]])
    assert session.wait_applied(30)
    panel.refresh()
    assert session.n_controls > 6 and numbers(panel) == ["0", "2", "3", "4", "5", "6"]
    assert panel.controls_html.value.count("~") == 1  # the stroke's row, marked
    assert "6 controls" in panel.status.value  # the status counts the table's rows, a stroke as one
    session.add_control([0.3, 0.9, -0.3])  # a double click: the number after the table's highest
    assert session.wait_applied(30)
    panel.refresh()
    assert numbers(panel) == ["0", "2", "3", "4", "5", "6", "7"] and "7 controls" in panel.status.value
    session.remove_control(session.n_controls - 1)
    assert session.wait_applied(30)
    panel.refresh()
    assert panel.radius_of.options[-1] == ("6 (stroke)", first)
    panel.radius_of.value = first
    panel.radius.value = 0.3  # the stroke's radius: every sample's
    assert session.control_edits.radii[first:] == pytest.approx([0.3] * (session.n_controls - first))


def test_all_radii_follows_a_preset_switch_and_a_group_change_is_told(panel):
    session = panel.session
    panel.all_radii.value = "0.5"
    assert session.wait_applied(30)
    panel.refresh()
    assert panel.all_radii.value == "0.5"
    labels = [label for label, _ in panel.preset.options]
    assert {"Tube (open)", "Cone (open)", "Disc (flat, open)", "Bowl (half sphere, open)"} <= set(labels)
    panel.preset.value = "torus"
    assert session.wait_applied(30)
    panel.refresh()
    assert float(panel.all_radii.value) == pytest.approx(get_preset("torus").radius, rel=1e-3)
    panel.group.value = "mirror-y"
    panel.refresh()
    assert "6 controls kept" in panel.error.value and "2 and 3" in panel.error.value
    assert session.n_controls == 6 and session.wait_applied(30)
    panel.refresh()
    assert "6 controls (12 with their copies)" in panel.status.value


def test_the_buttons_say_what_they_do_in_the_web_pages_words(panel):
    """A person moving between the notebook and the web page reads the same tooltip on each button."""
    from somwidget.frontend.model.panel import ACTION_HELP

    assert panel.reset_button.tooltip == ACTION_HELP["reset"]
    assert "controls stay" in panel.reset_button.tooltip
    assert panel.reload_button.tooltip == ACTION_HELP["reload_preset"]
    assert panel.undo_button.tooltip == ACTION_HELP["undo"] and "Ctrl+Z" in panel.undo_button.tooltip
    assert panel.refine_button.tooltip == ACTION_HELP["refine"]


def test_a_control_off_the_clay_has_its_gap_marked_as_on_the_web_page(panel):
    """The web page marks the gap cell of a control farther than 3% of the size from the clay; so does the notebook."""
    from somwidget.frontend.model.panel import OFF_CLAY_STYLE

    session = panel.session
    session.pause()
    panel.refresh()
    assert OFF_CLAY_STYLE not in panel.controls_html.value  # the preset's controls sit on the clay
    session.move_control(2, [0.0, 0.0, 2.5])  # far above the sphere, paused: nothing follows it
    assert session.wait_applied(30)
    panel.refresh()
    rows = panel.controls_html.value.split("<tr>")[2:]  # after the header
    marked = [r for r in rows if OFF_CLAY_STYLE in r]
    assert len(marked) == 1 and re.match(r"<td[^>]*>2<", marked[0]), marked
