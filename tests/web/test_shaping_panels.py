"""Shaping from the panels (issue "Shaping": the radius column, the symmetry choice) as a person uses them: the web app
in Chromium (Playwright types a radius into the controls table and picks a group from the menu; the server's state
is read back through GET /api/state), and the notebook's ipywidgets panel (its widgets set as a person would)."""

from __future__ import annotations

import os
import re

import numpy as np
import pytest
from helpers import CHROMIUM, CHROMIUM_ARGS, Serve, wait_for, wave_mesh

from somwidget.frontend.model import Session
from somwidget.frontend.notebook import Panel

pytestmark = pytest.mark.browser

playwright_sync = pytest.importorskip("playwright.sync_api", reason="Python Playwright is not installed")


@pytest.mark.skipif(not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} is missing")
def test_the_web_panel_sets_a_radius_and_a_symmetry_group():
    srv = Serve("--preset", "sphere")
    try:
        with playwright_sync.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": 1200, "height": 900})
            page.goto(srv.url)
            page.wait_for_selector("#controls-table .radius-cell input", timeout=30000)
            radius = page.locator("#controls-table tr").nth(2).locator(".radius-cell input")
            radius.fill("0.55")
            radius.press("Enter")
            srv.wait(lambda s: abs(s["session"]["radii"][2] - 0.55) < 1e-6, what="control 2's radius")
            srv.idle()
            radius.fill("-1")  # refused: the message in the panel, the radius as it was
            assert radius.input_value() == "-1", "the field lost what was typed before Enter"
            radius.press("Enter")
            page.wait_for_function("() => document.querySelector('#error-alert')?.innerText.includes('radius')")
            assert abs(srv.state()["session"]["radii"][2] - 0.55) < 1e-6
            steps = srv.idle()["session"]["history"][0]
            every = page.locator("#all-radii")  # every control's radius at once: one step
            every.fill("0.7")
            every.press("Enter")
            st = srv.wait(lambda s: np.allclose(s["session"]["radii"], 0.7, atol=1e-6), what="every radius 0.7")
            assert srv.idle()["session"]["history"][0] == steps + 1
            page.wait_for_function("() => [...document.querySelectorAll('#controls-table .radius-cell input')]"
                                   ".every((e) => Math.abs(Number(e.value) - 0.7) < 1e-6)", timeout=10000)
            page.locator(".v-select:has(#symmetry-group) .v-field").click()
            page.locator(".v-list-item", has_text="4-fold about z").first.click()
            st = srv.wait(lambda s: s["session"]["parameters"]["group"] == "radial-4-z", what="the radial group")
            assert len(st["session"]["frame"]["effective_controls"]) == 4 * len(st["session"]["controls"])
            page.locator("#symmetry-switch").click()  # off: each copy a control of its own
            srv.wait(lambda s: s["session"]["parameters"]["group"] == "none"
                     and len(s["session"]["controls"]) == len(st["session"]["frame"]["effective_controls"]),
                     what="the group off")
            n = st["session"]["n_vertices"]
            page.locator("#refine").click()  # every face split: the clay keeps its shape with four times the faces
            st = srv.wait(lambda s: s["session"]["n_vertices"] > 3 * n
                          and s["session"]["preset"].endswith("(refined)"), what="the refined clay")
            page.wait_for_function("() => document.getElementById('clay-view').somview.describe().generation >= "
                                   f"{st['session']['generation']}", timeout=20000)  # the view draws the new mesh
            browser.close()
    finally:
        srv.stop()


def test_the_notebook_panel_sets_a_radius_and_a_symmetry_group():
    session = Session("sphere", device="cpu", autosave=False)
    panel = Panel(session, auto_refresh=False)
    try:
        assert [label for label, _ in panel.group.options][:4] == ["off", "mirror across x", "mirror across y",
                                                                   "mirror across z"]
        panel.radius_of.value = 3
        panel.radius.value = 0.4
        assert session.control_edits.radii[3] == pytest.approx(0.4)
        panel.group.value = "radial-8-z"
        assert session.parameters["group"] == "radial-8-z"
        assert session.wait_applied(30)
        panel.refresh()
        assert "radius" in panel.controls_html.value
        shown = [float(x) for x in re.findall(r'somwidget-radius">([0-9.e+-]+)<', panel.controls_html.value)]
        np.testing.assert_allclose(shown, session.control_edits.radii, rtol=1e-2)
        steps = session.history[0]
        panel.all_radii.value = "0.3"  # every control's radius at once: one step
        np.testing.assert_allclose(session.control_edits.radii, 0.3)
        assert session.history[0] == steps + 1
        panel.all_radii.value = "-1"  # refused: the message, the radii as they were
        assert "radius" in panel.error.value
        np.testing.assert_allclose(session.control_edits.radii, 0.3)
        panel.radius.value = 2e6  # past the widget's bound (a few sizes): it holds the radius there
        assert session.control_edits.radii.max() <= 2.0 * panel.model.size + 1e-4
        panel.symmetry.value = False
        assert session.parameters["group"] == "none"
        wait_for(lambda: session.wait_applied(1), what="the group off applied")
        n = session.preset.n_vertices
        panel.refine_button.click()
        assert session.preset.n_vertices > 3 * n and "(refined)" in panel.preset.label
    finally:
        panel.close()
        session.close()


@pytest.mark.skipif(not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} is missing")
def test_a_mesh_past_the_limit_is_offered_decimated(tmp_path):
    """An upload with more vertices than the session takes is refused with the figures, and the panel offers to load
    it decimated: pressing Decimate loads it with at most the limit, its shape kept."""
    big = wave_mesh(tmp_path / "wave.ply", 513)  # 263,169 vertices > 262,144 on the CPU
    srv = Serve()
    try:
        with playwright_sync.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": 1200, "height": 900})
            page.goto(srv.url)
            page.wait_for_selector("#mesh-upload", timeout=30000)
            page.locator("#mesh-upload").set_input_files(str(big))
            page.wait_for_function("() => document.querySelector('#error-alert')?.innerText.includes('263,169')",
                                   timeout=30000)
            assert "decimated" in page.locator("#error-alert").inner_text()
            page.locator("#decimate-upload").click()
            st = srv.wait(lambda s: s["session"]["preset"].startswith("mesh:wave"), timeout=60, what="decimated mesh")
            assert 100_000 < st["session"]["n_vertices"] <= 262_144
            assert "decimated from 263,169" in page.locator("body").inner_text()
            browser.close()
    finally:
        srv.stop()
