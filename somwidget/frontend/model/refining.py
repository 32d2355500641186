"""The clay refined: the preset a session continues from after `Session.refine` (its mesh subdivided by
backend/refine.py, the shape as the session holds it now as the new start, its controls, radii, symmetry and
schedule kept)."""

from __future__ import annotations

import dataclasses

import numpy as np

from ...backend import refine as _refine
from ...backend.presets import Preset
from ...backend.schedule import KEYS as SCHEDULE_KEYS
from ...backend.topology import Topology

SUFFIX = " (refined)"


def refined_preset(snapshot: dict, stretched: float | None, max_vertices: int) -> Preset:
    """A session's snapshot refined (every face, or only the edges stretched past `stretched` times the median);
    ValueError for a clay without faces or past `max_vertices`."""
    preset: Preset = snapshot["preset"]
    if preset.display != "surface" or not preset.topology.faces:
        raise ValueError(f"refine: the clay ({preset.title}) is drawn as {preset.display} without faces to split; "
                         "refine works on a surface")
    if stretched is None:
        faces, weights = _refine.subdivide(preset.topology.faces, snapshot["weights"])
    else:
        faces, weights = _refine.refine_stretched(preset.topology.faces, snapshot["weights"], stretched,
                                                  preset.layout.position)
    if len(weights) > max_vertices:
        raise ValueError(f"refine: the refined clay would have {len(weights):,} nodes; this session takes at most "
                         f"{max_vertices:,} on its device")
    p, group = snapshot["parameters"], snapshot["symmetry"]
    return dataclasses.replace(
        preset, name=preset.name if preset.name.endswith(SUFFIX) else preset.name + SUFFIX,
        title=preset.title if preset.title.endswith(SUFFIX) else preset.title + SUFFIX,
        description=f"{preset.description} Refined to {len(weights):,} nodes.",
        topology=Topology.from_faces(faces, len(weights)), weights=weights, controls=snapshot["controls"],
        radii=snapshot["radii"], strokes=snapshot["strokes"], grow=False, mirror=tuple(p["mirror"]),
        symmetry=group if group is not None and group.kind == "radial" else None,
        metric_weights=np.asarray(p["metric_weights"], np.float32), smoothing_rule=snapshot["smoothing_rule"],
        **{key: p[key] for key in SCHEDULE_KEYS})
