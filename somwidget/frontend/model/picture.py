"""Static pictures of a SOM without any UI: an off-screen pyvista render returned as an image (and saved if asked).

    import somwidget
    img = somwidget.render(som, "result.png")          # (H, W, 3) uint8; also written to result.png

`render` takes a `Som`, a `Session` (or anything with a `.session`, such as the widget `show()` returns), a
`Preset` or a preset name, and draws what the app draws: the mesh (surface, lines or points, with the colours of
the colour dims), the controls as spheres and their mirrored copies as paler spheres. Headless machines render
through EGL (VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow, set here on Linux without a display).
"""

from __future__ import annotations

import os
import sys

if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

from dataclasses import dataclass  # noqa: E402

import numpy as np  # noqa: E402

from ...backend import presets as _presets  # noqa: E402
from ...backend.presets import FeatureLayout, Preset  # noqa: E402
from ...backend.topology import Topology  # noqa: E402

#: The pictures' background: the clay view's, so a picture looks like the live view.
BACKGROUND = (0.933, 0.941, 0.957)
#: The clay's material and edges as the live view shows them (its hemisphere light keeps the shaded side bright, its
#: wireframe is a faint dark line over the colours).
CLAY_LOOK = {"ambient": 0.45, "diffuse": 0.7, "specular": 0.1}
EDGE_COLOUR = (0.5, 0.5, 0.56)


def cell_array(faces) -> np.ndarray:
    """pyvista's flat cell array [k, i0, ..., ik-1, ...] from faces of any size (list or (F, k) array)."""
    if isinstance(faces, np.ndarray) and faces.ndim == 2:
        f = np.asarray(faces, np.int64)
        return np.hstack([np.full((len(f), 1), f.shape[1], np.int64), f]).ravel()
    parts = []
    for face in faces:
        face = np.asarray(face, np.int64).ravel()
        parts.append(np.concatenate([[len(face)], face]))
    return np.concatenate(parts) if parts else np.zeros(0, np.int64)


#: Named camera directions (from the centre towards the camera) and up vectors.
CAMERAS = {
    "iso": ((0.55, -1.0, 0.55), (0.0, 0.0, 1.0)),  # the app's starting view
    "front": ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),  # from +x
    "side": ((0.0, -1.0, 0.0), (0.0, 0.0, 1.0)),  # from -y, the xz-plane face on
    "top": ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),  # from +z
}


@dataclass
class Picture:
    """What to draw: node weights on a topology with a feature layout, and the controls."""

    weights: np.ndarray
    topology: Topology
    layout: FeatureLayout
    display: str
    controls: np.ndarray
    effective_controls: np.ndarray


def default_layout(n_dims: int) -> FeatureLayout:
    """x, y, z in dims 0..2, any further dims plain features (no colour)."""
    if n_dims < 3:
        raise ValueError(f"render: a picture needs 3 position dims; these weights have {n_dims} (pass layout=)")
    names = ("x", "y", "z") + tuple(f"f{d}" for d in range(3, n_dims))
    return FeatureLayout(names=names, position=(0, 1, 2), colour=(), colour_space="none")


def _default_display(topology: Topology, layout: FeatureLayout) -> str:
    if layout.direction:
        return "lines"
    return "surface" if topology.faces else "points"


def picture_of(what, *, weights=None, layout: FeatureLayout | None = None, display: str | None = None) -> Picture:
    """The `Picture` of a Som, Session (or object with `.session`), Preset or preset name; `weights` overrides."""
    from ...backend.som import Som

    if hasattr(what, "session") and not isinstance(what, (Som, Preset)):
        what = what.session
    if isinstance(what, str):
        what = _presets.get_preset(what)
    if isinstance(what, Preset):
        layout = layout or what.layout
        pic = Picture(what.weights, what.topology, layout, display or what.display, what.controls,
                      what.effective_controls())
    elif isinstance(what, Som):
        layout = layout or default_layout(what.n_dims)
        pic = Picture(what.weights, what.topology, layout, display or _default_display(what.topology, layout),
                      what.controls, what.effective_controls)
    elif hasattr(what, "frame") and hasattr(what, "preset"):  # a Session: its latest frame
        frame = what.frame
        layout = layout or what.layout
        pic = Picture(np.asarray(frame.weights), what.topology, layout, display or what.preset.display,
                      np.asarray(frame.controls), np.asarray(frame.effective_controls))
    else:
        raise ValueError(f"render: expected a Som, a Session, a Preset or a preset name, got {type(what).__name__}")
    if weights is not None:
        w = np.asarray(weights, np.float32)
        if w.shape != (pic.topology.n_vertices, pic.layout.n_dims):
            raise ValueError(f"render: weights have shape {w.shape}, expected "
                             f"({pic.topology.n_vertices}, {pic.layout.n_dims})")
        pic.weights = w
    if pic.display not in _presets.DISPLAYS:
        raise ValueError(f"render: display must be one of {_presets.DISPLAYS}, got {pic.display!r}")
    if pic.display == "lines" and not pic.layout.direction:
        raise ValueError("render: display 'lines' needs a layout with direction dims")
    if pic.display == "surface" and not pic.topology.faces:
        pic.display = "points"
    return pic


def _control_colours(pic: Picture) -> tuple[np.ndarray, np.ndarray]:
    if pic.layout.colour_space != "none":
        return _presets.colours_of(pic.controls, pic.layout), _presets.colours_of(pic.effective_controls, pic.layout)
    return _presets.palette_colours(len(pic.controls), len(pic.effective_controls))


def render(what, path=None, *, weights=None, layout: FeatureLayout | None = None, display: str | None = None,
           controls: bool = True, size=(800, 600), camera="iso", zoom: float = 1.0, edges: bool = True,
           background=BACKGROUND, title: str | None = None) -> np.ndarray:
    """Draw a SOM off-screen and return the image, (H, W, 3) uint8; write it to `path` (PNG, JPEG...) if given.

    what:     a Som (its current weights), a Session (its latest frame) or an object with `.session` (the widget
              of `show()`), a Preset or a preset name (the start mesh)
    weights:  draw these (N, n) weights instead (e.g. a copy taken earlier in a run)
    layout:   the FeatureLayout of a bare Som (default: x, y, z in dims 0..2, no colour)
    display:  "surface", "lines" or "points" (default: the preset's; for a bare Som lines when the layout has
              direction dims, else the faces, else points)
    controls: draw the controls (spheres) and their mirrored copies (paler)
    camera:   "iso" (the app's view), "front", "side", "top", or a pyvista camera position
              [(position), (focal point), (view up)]
    zoom:     > 1 comes closer; edges: draw the mesh edges on surfaces; title: text in the top-left corner
    """
    import pyvista as pv

    pic = picture_of(what, weights=weights, layout=layout, display=display)
    positions = _presets.positions_of(pic.weights, pic.layout)
    rgb = np.clip(np.round(_presets.colours_of(pic.weights, pic.layout) * 255), 0, 255).astype(np.uint8)
    width, height = (int(size[0]), int(size[1]))
    pl = pv.Plotter(off_screen=True, window_size=[width, height])
    try:
        pl.set_background(background)
        if pic.display == "lines":
            pts, quads = _presets.line_display_mesh(pic.weights, pic.topology, pic.layout)
            n = len(positions)
            both = np.concatenate([rgb, rgb])
            sheet = pv.PolyData(pts, faces=cell_array(quads))
            sheet.point_data["rgb"] = both
            pl.add_mesh(sheet, scalars="rgb", rgb=True, opacity=0.8, **CLAY_LOOK)
            segs = np.hstack([np.full((n, 1), 2), np.arange(n)[:, None], np.arange(n, 2 * n)[:, None]]).ravel()
            strokes = pv.PolyData(pts, lines=segs)
            strokes.point_data["rgb"] = both
            pl.add_mesh(strokes, scalars="rgb", rgb=True, line_width=2)
            shown = pts
        elif pic.display == "points":
            cloud = pv.PolyData(positions)
            cloud.point_data["rgb"] = rgb
            pl.add_mesh(cloud, scalars="rgb", rgb=True, style="points", point_size=6, render_points_as_spheres=True)
            e = np.asarray(pic.topology.edges, np.int64).reshape(-1, 2)
            if len(e):
                net = pv.PolyData(positions, lines=np.hstack([np.full((len(e), 1), 2), e]).ravel())
                net.point_data["rgb"] = rgb
                pl.add_mesh(net, scalars="rgb", rgb=True, line_width=1, opacity=0.5)
            shown = positions
        else:
            surface = pv.PolyData(positions, faces=cell_array(pic.topology.faces))
            surface.point_data["rgb"] = rgb
            pl.add_mesh(surface, scalars="rgb", rgb=True, show_edges=edges, edge_color=EDGE_COLOUR, line_width=0.5,
                        **CLAY_LOOK)
            shown = positions
        everything = shown
        if controls and len(pic.effective_controls):
            cpos = _presets.positions_of(pic.controls, pic.layout)
            epos = _presets.positions_of(pic.effective_controls, pic.layout)
            everything = np.concatenate([shown, epos])
            span = float(np.linalg.norm(everything.max(axis=0) - everything.min(axis=0))) or 1.0
            own, eff = _control_colours(pic)
            k = len(cpos)
            for j, p in enumerate(epos):
                ball = pv.Sphere(radius=0.035 * span, center=tuple(float(x) for x in p), theta_resolution=24,
                                 phi_resolution=16)
                colour = tuple(float(c) for c in (own[j] if j < k else eff[j]))
                pl.add_mesh(ball, color=colour, opacity=1.0 if j < k else 0.55, specular=0.4)
        _place_camera(pl, everything, camera, zoom)
        if title:
            pl.add_text(str(title), position="upper_left", font_size=12, color=(0.15, 0.15, 0.2))
        img = pl.screenshot(filename=None, return_img=True)
    finally:
        pl.close()
    img = np.ascontiguousarray(np.asarray(img)[..., :3], dtype=np.uint8)
    if path is not None:
        save_image(path, img)
    return img


def _place_camera(pl, points: np.ndarray, camera, zoom: float) -> None:
    lo, hi = points.min(axis=0), points.max(axis=0)
    centre = (lo + hi) / 2.0
    span = float(np.linalg.norm(hi - lo)) or 1.0
    if isinstance(camera, str):
        if camera not in CAMERAS:
            raise ValueError(f"render: camera must be one of {', '.join(CAMERAS)} or a camera position, "
                             f"got {camera!r}")
        direction, up = CAMERAS[camera]
        d = np.asarray(direction, np.float64)
        d /= np.linalg.norm(d)
        pl.camera_position = [tuple(centre + d * span * 1.6), tuple(centre), up]
    else:
        pl.camera_position = camera
    if zoom != 1.0:
        pl.camera.zoom(float(zoom))
    pl.reset_camera_clipping_range()


def png_bytes(img: np.ndarray) -> bytes:
    """An (H, W, 3) uint8 image as PNG bytes."""
    import io

    from PIL import Image  # pyvista's own dependency

    buffer = io.BytesIO()
    Image.fromarray(np.asarray(img, np.uint8)).save(buffer, format="PNG")
    return buffer.getvalue()


def save_image(path, img: np.ndarray) -> None:
    """Write an (H, W, 3) uint8 image; the format follows the extension (PNG, JPEG, BMP, TIFF...)."""
    from PIL import Image  # pyvista's own dependency

    os.makedirs(os.path.dirname(os.path.abspath(os.fspath(path))), exist_ok=True)
    Image.fromarray(np.asarray(img, np.uint8)).save(os.fspath(path))


__all__ = ["render", "picture_of", "Picture", "default_layout", "save_image", "png_bytes", "CAMERAS"]
