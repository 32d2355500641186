"""Recovery cannot lose work, whatever is on the disk (issue 38, item 5): hypothesis draws one to three damages of a
stopped session's folder (autosave_damage.py: each field of the manifest set to an adversarial value, deleted or
added to; the manifest's text cut or replaced; each array of a step or preset file past the engine's bounds, NaN,
another type or shape, members taken out or added; files cut short, random, folders, links in and out of the
folder, named pipes, removed; the lock and stray files), and a restart (Session.recover in this process, as
`somwidget serve` calls it) must: start; bring back finite weights and controls that are one of the saved steps (the
current one when no damage could touch it); and change or delete no byte of the saved folder (it is read in place,
or set aside whole, and what came back of it is whole in a new folder).

CI runs SOMWIDGET_FUZZ_EXAMPLES examples (default 100: about 30 s on 2 cores); benchmarks/fuzz_recovery.py runs a
seeded generator of the same damages for longer."""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import pytest

hypothesis = pytest.importorskip("hypothesis", reason="hypothesis is in the [test] extra")
from autosave_damage import (  # noqa: E402
    ARRAY,
    FILE,
    FOLDER,
    TEXT,
    VALUES,
    Damage,
    Saved,
    make_saved,
    nodes,
    recover_damaged,
)
from hypothesis import HealthCheck, Phase, event, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

EXAMPLES = int(os.environ.get("SOMWIDGET_FUZZ_EXAMPLES", "100"))
#: Where each example's folder goes: memory where there is a tmpfs (the checks are the same, the fsyncs free).
SCRATCH = "/dev/shm" if os.path.isdir("/dev/shm") and os.access("/dev/shm", os.W_OK) else None
ROLES = ("current", "undo:0", "undo:1", "undo:2", "undo:5", "redo:0", "preset:0", "preset:1", "manifest")


@pytest.fixture(scope="module")
def saved(tmp_path_factory) -> Saved:
    root = tmp_path_factory.mktemp("fuzz-saved")
    old = os.environ.get("SOMWIDGET_DATA_DIR")
    os.environ["SOMWIDGET_DATA_DIR"] = str(root)
    try:
        return Saved.of(make_saved(root))
    finally:
        os.environ["SOMWIDGET_DATA_DIR"] = old


def damages(manifest: dict):
    """A strategy of one damage to a folder whose manifest is `manifest`."""
    paths = st.sampled_from(nodes(manifest))
    numbers = st.integers(0, 1 << 20)
    values = st.one_of(st.sampled_from(VALUES), st.integers(), st.floats(), st.text(max_size=20))
    return st.one_of(
        st.builds(Damage, st.just("set"), paths, st.just(""), values, numbers),
        st.builds(Damage, st.sampled_from(("delete", "add")), paths, st.just(""), values, numbers),
        st.builds(Damage, st.just("text"), st.just(("manifest",)), st.sampled_from(TEXT), st.none(), numbers),
        st.builds(Damage, st.just("array"), st.tuples(st.sampled_from(ROLES[:-1])), st.sampled_from(ARRAY), st.none(),
                  numbers),
        st.builds(Damage, st.just("file"), st.tuples(st.sampled_from(ROLES)), st.sampled_from(FILE), st.none(),
                  numbers),
        st.builds(Damage, st.just("folder"), st.just(()), st.sampled_from(FOLDER), st.none(), numbers),
    )


def test_the_saved_folder_is_a_session_with_every_kind_of_step(saved):
    """What the damages act on: two meshes' starts, undo and redo steps, a radial group, a stroke, radii."""
    m = saved.manifest
    assert len(m["presets"]) == 2 and len(m["undo"]) >= 6 and len(m["redo"]) == 1
    steps = [m["current"], *m["undo"], *m["redo"]]
    assert any(s["symmetry"] and s["symmetry"]["kind"] == "radial" for s in steps)
    assert any(s["strokes"] and max(s["strokes"]) > 1 for s in steps)


def test_an_undamaged_folder_comes_back_whole_and_unchanged(saved, tmp_path):
    assert recover_damaged(saved, [], tmp_path).outcome == "whole"


@settings(max_examples=EXAMPLES, deadline=None, database=None, print_blob=True,
          phases=(Phase.explicit, Phase.generate, Phase.shrink),
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow, HealthCheck.data_too_large])
@given(data=st.data())
def test_any_damage_starts_and_loses_nothing(saved, data):
    drawn = data.draw(st.lists(damages(saved.manifest), min_size=1, max_size=3), label="damages")
    work = Path(tempfile.mkdtemp(prefix="fuzz-", dir=SCRATCH))
    try:
        event(recover_damaged(saved, drawn, work).outcome)  # --hypothesis-show-statistics counts the outcomes
    finally:
        shutil.rmtree(work, ignore_errors=True)
