"""somwidget: a self-organizing map as computational clay (after Felbrich et al., IEEE AIVR 2018).

Compute lives in somwidget.backend (numpy + warp only); the views in somwidget.frontend. `import somwidget` loads
no UI package: `show` (Jupyter) and `render` (static pictures) import theirs when called.
"""

from .backend import presets
from .backend.som import Som
from .backend.symmetry import Symmetry
from .backend.topology import Topology


def show(what="car", **kwargs):
    """The interactive SOM in a Jupyter cell: a panel beside the live, draggable view of one Session.

    See somwidget.frontend.notebook.show for the arguments."""
    from .frontend.notebook import show as _show

    return _show(what, **kwargs)


def render(what, path=None, **kwargs):
    """An off-screen picture of a Som, Session, Preset or preset name: (H, W, 3) uint8, saved to `path` if given.

    See somwidget.frontend.model.picture.render for the arguments."""
    from .frontend.model.picture import render as _render

    return _render(what, path, **kwargs)


def sweep(preset_or_session="car", n: int = 64, jitter: float = 0.05, params=None, seed: int = 0, device=None,
          client=None, **kwargs):
    """Train n design variants at once (batched on the GPU, or over a Dask cluster with `client`) and return them as
    `Variants`: controls, weights, params, metrics, picture(), apply(i) / session(i).

    See somwidget.frontend.model.variants.sweep for the arguments."""
    from .frontend.model.variants import sweep as _sweep

    return _sweep(preset_or_session, n=n, jitter=jitter, params=params, seed=seed, device=device, client=client,
                  **kwargs)


def serve(preset: str | None = None, mesh=None, host: str | None = None, port: int = 8080, device: str = "auto",
          open_browser: bool = False, lan: bool = False, fresh: bool = False):
    """Run the web app (what `somwidget serve` runs) until interrupted; see somwidget.frontend.web.serve.run_server."""
    from .frontend.web.serve import run_server

    return run_server(preset=preset, mesh=mesh, host=host, port=port, device=device, open_browser=open_browser,
                      lan=lan, fresh=fresh)


def join(url: str, timeout: float = 30.0, fingerprint: str | None = None, verify: bool = True):
    """A room of a running studio (`somwidget serve --studio`) by its link (https://host:8080/r/<name>/?token=...):
    a proxy of its session whose intents and frames go over the room's websocket; `.show()` draws it in a notebook.

    See somwidget.frontend.studio.remote for the arguments."""
    from .frontend.studio.remote import join as _join

    return _join(url, timeout=timeout, fingerprint=fingerprint, verify=verify)


def __getattr__(name: str):
    """`somwidget.Session`: the modelling session every view shares (imported on first use; no UI package)."""
    if name == "Session":
        from .frontend.model import Session

        return Session
    raise AttributeError(f"module 'somwidget' has no attribute {name!r}")


__all__ = ["Som", "Topology", "Symmetry", "Session", "presets", "serve", "show", "render", "sweep", "join"]
