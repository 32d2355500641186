"""A session summed up as JSON: what the web app's /api/state route, the tests and the benchmarks read."""

from __future__ import annotations


def summary(session, positions: bool = False) -> dict:
    """A JSON-friendly summary of a session (`Session.state`: debug routes, tests); `positions` adds every node's
    x, y, z."""
    frame, state = session.frame, session.modelling
    with state.lock:
        controls, params, pending = state.controls.copy(), state.parameters(), len(session.trainer.ops)
        radii, strokes = state.radii.tolist(), list(state.strokes)
    layout, preset = state.layout, state.preset
    out = {
        "preset": preset.name, "title": preset.title, "display": preset.display, "generation": frame.generation,
        "n_vertices": int(preset.n_vertices), "n_dims": layout.n_dims, "feature_names": list(layout.names),
        "position_dims": list(layout.position), "colour_dims": list(layout.colour),
        "colour_space": layout.colour_space, "controls": controls.tolist(), "radii": radii, "strokes": strokes,
        "parameters": params, "paused": state.paused, "pending_intents": pending,
        "frame": {
            "seq": frame.seq, "iteration": frame.iteration, "iterations": frame.iterations,
            "running": frame.running, "cycle_time": frame.cycle_time,
            "controls": frame.controls.tolist(), "effective_controls": frame.effective_controls.tolist(),
            "gaps": frame.gaps.tolist(), "centroid": frame.positions.mean(axis=0).tolist(),
        },
        "frames_per_second": session.frames_per_second, "error": session.error,
        "history": list(frame.history), "held": frame.held, "recovered": session.recovered is not None,
        "recovered_message": (session.recovered or {}).get("message", ""), "notices": list(session.notices),
        "autosave": {"path": None if session.autosave is None else str(session.autosave.path),
                     "error": session.save_error},
    }
    if positions:
        out["frame"]["positions"] = frame.positions.tolist()
    return out
