"""A room's page in Chromium, acted on with the mouse as a person does: press on a control (or its mirrored copy
where the clay hides it) and drag it."""

from __future__ import annotations


def press_on(page, index: int, k: int) -> tuple[float, float]:
    """The mouse pressed on control `index` (or its mirrored copy where the clay hides it); k: the room's controls."""
    for j in (index, index + k):
        at = page.evaluate(f"somxr.controlScreen({j})")
        if at is None:  # no such copy drawn (a clay without a mirror)
            continue
        x, y = at
        page.mouse.move(x, y)
        try:  # the page lights the control up under the pointer (seconds on a loaded machine)
            page.wait_for_function(f"somxr.state().hover.some((j) => j % {k} === {index})", timeout=8000)
        except Exception:
            continue
        page.mouse.down()
        return x, y
    raise AssertionError(f"control {index} cannot be taken with the mouse")


def drag(page, index: int, k: int) -> None:
    """Control `index` dragged up and to the right in nine moves 40 ms apart, then let go."""
    x, y = press_on(page, index, k)
    for s in range(1, 10):
        page.mouse.move(x + 8 * s, y - 5 * s)
        page.wait_for_timeout(40)
    page.mouse.up()
