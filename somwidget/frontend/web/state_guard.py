"""What a browser may write into the web app's trame state: the keys its own widgets bind, with the types they
send. trame takes any key from any client and pushes it to every other tab (the page template included), so the
app puts `filter_changes` in front of trame's "trame.state.update": anything else is dropped and logged, and the
session and the other tabs carry on.
"""

from __future__ import annotations

import logging
import math

from ...backend.schedule import SETTINGS
from ..model.panel import EXPORT_CHOICES

log = logging.getLogger(__name__)

MAX_TEXT = 200  # characters in a field's text or a preset name


def _text(value) -> bool:
    return isinstance(value, str) and len(value) <= MAX_TEXT


def _number_or_text(value) -> bool:
    if isinstance(value, bool):
        return False
    if isinstance(value, (int, float)):
        return math.isfinite(value)
    return _text(value)


def _flag(value) -> bool:
    return isinstance(value, bool)


def _cleared(value) -> bool:
    """A message a tab may only clear (its close button), never write."""
    return value == ""


def _file(value) -> bool:
    """A file input's value: nothing, or trame's file dict(s) (name, size, type, content); the app checks the rest."""
    if value is None:
        return True
    items = value if isinstance(value, list) else [value]
    return len(items) <= 1 and all(isinstance(v, dict) and len(v) <= 8 and all(isinstance(k, str) for k in v)
                                   for v in items)


def _number(value) -> bool:
    return not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)


def state_key(name: str) -> str:
    """The trame state key of a setting's field."""
    return "param_S" if name == "iterations" else f"param_{name}"


#: The settings' widgets the page binds both ways (the others send triggers): the value each may write.
_BOUND = {"slider": _number, "switch": _flag, "choice": _text}


#: key -> check of the value a client may send for it
WRITABLE = {
    "main_drawer": _flag,
    "preset_name": _text,
    "mesh_upload": _file,
    "session_upload": _file,
    **{state_key(s.name): _BOUND[s.widget] for s in SETTINGS if s.widget in _BOUND},
    "variants_n": _number_or_text,
    "variants_jitter": _number_or_text,
    "export_format": lambda value: value in dict(EXPORT_CHOICES),
    "variants_vary": lambda value: isinstance(value, list) and len(value) <= 5 and all(
        isinstance(v, str) and len(v) <= 16 for v in value),
    "error_message": _cleared,
    "info_message": _cleared,
    "recovered_message": _cleared,
    "notice_message": _cleared,
}


def filter_changes(changes) -> tuple[list[dict], list[str]]:
    """(the changes a client may make, the keys refused) from trame's [{"key": k, "value": v}, ...]."""
    allowed: list[dict] = []
    refused: list[str] = []
    if not isinstance(changes, list):
        return allowed, ["<not a list>"]
    for change in changes:
        key = change.get("key") if isinstance(change, dict) else None
        check = WRITABLE.get(key) if isinstance(key, str) else None
        if check is not None and check(change.get("value")):
            allowed.append(change)
        else:
            refused.append(str(key)[:60])
    return allowed, refused


def guard_state_updates(wslink_server) -> bool:
    """Put `filter_changes` in front of trame's "trame.state.update" on every websocket handler of the wslink
    server (what trame's `on_server_bind` passes). False where there is none to guard (wslink's internals moved:
    the tests' attack then fails)."""
    handlers = getattr(wslink_server, "_ws_handlers", None) or []
    guarded = False
    for handler in handlers:
        table = getattr(handler, "functionMap", None)
        if not isinstance(table, dict):
            continue
        entry = table.get("trame.state.update")
        if entry is None:
            continue
        obj, update = entry

        def filtered(self, changes, _update=update):
            allowed, refused = filter_changes(changes)
            if refused:
                log.warning("refused a client's state update for %s", ", ".join(refused))
            if allowed:
                return _update(self, allowed)
            return None

        table["trame.state.update"] = (obj, filtered)
        guarded = True
    return guarded
