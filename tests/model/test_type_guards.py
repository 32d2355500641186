"""The guards that replaced unchecked Optional reads (found by mypy): each names what is missing in plain words
instead of an AttributeError on None."""

from __future__ import annotations

import threading

import pytest

from somwidget.backend.schedule import BY_NAME, Setting
from somwidget.frontend.model.frames import FrameStream


def test_a_frame_stream_before_its_first_frame_says_so():
    with pytest.raises(RuntimeError, match="no frame yet"):
        FrameStream(threading.Condition()).latest  # noqa: B018


def test_a_setting_without_a_slider_is_refused_by_name_where_a_panel_wants_one():
    assert BY_NAME["reach"].slider_range() == BY_NAME["reach"].slider
    with pytest.raises(ValueError, match="^plain: declared without a slider"):
        Setting("plain", "plain", "float").slider_range()

