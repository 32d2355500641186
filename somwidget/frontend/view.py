"""The pyvista scene of a session: the clay mesh, the controls as draggable sphere widgets, their mirrored copies.

`SceneView` owns an off-screen `pyvista.Plotter`. It is not thread-safe: build it, `apply` frames to it and
render it on one thread (the trame server's event loop). Dragging a sphere widget sends `move_control` intents to
the session; the clay follows through the frames that come back.

Headless rendering uses EGL (Mesa llvmpipe without a GPU): VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow must be
set before VTK creates its first window, which importing this module does unless the variable is set already.
"""

from __future__ import annotations

import os

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

import numpy as np  # noqa: E402
import pyvista as pv  # noqa: E402
from vtkmodules.vtkInteractionWidgets import vtkSphereWidget  # noqa: E402

from ..backend import presets as _presets  # noqa: E402
from .session import Frame, Session  # noqa: E402

BACKGROUND = (0.97, 0.97, 0.98)
SELECTED = (1.0, 1.0, 1.0)


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


def control_colours(frame: Frame, has_colour: bool) -> tuple[np.ndarray, np.ndarray]:
    """(k, 3) and (k_eff, 3) display colours of the controls and their mirrored copies (the palette of
    `presets.palette_colours` when the layout has no colour dims)."""
    if has_colour:
        return np.asarray(frame.control_colours), np.asarray(frame.effective_colours)
    return _presets.palette_colours(frame.n_controls, len(frame.effective_controls))


def _rgb8(colours: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(np.clip(np.round(np.asarray(colours) * 255.0), 0, 255).astype(np.uint8))


class SceneView:
    """The 3-D scene of one session, drawn by an off-screen pyvista Plotter."""

    def __init__(self, session: Session, window_size=(1000, 700)):
        self.session = session
        # no MSAA: with Mesa llvmpipe 8x multisampling triples the render time (90 ms against 30 at 1010 x 816)
        self.plotter = pv.Plotter(off_screen=True, window_size=list(window_size))
        self.plotter.render_window.SetMultiSamples(0)
        self.plotter.set_background(BACKGROUND)
        self.widgets: list[vtkSphereWidget] = []
        self.dragging: int | None = None
        self.drag_moves = 0  # widget interaction events seen (for tests and the debug route)
        self.on_drag = None  # optional callable(index | None) called when a drag starts (index) / ends (None)
        self._mirror_actors: list = []
        self._mesh: pv.PolyData | None = None
        self._meshes: list[pv.PolyData] = []
        self._generation = -1
        self._n_controls = -1
        self._radius = 0.1
        self._control_colours: np.ndarray | None = None
        self.frame: Frame | None = None

    # -- building -----------------------------------------------------------------------------------------------
    def build(self, frame: Frame) -> None:
        """(Re)build the whole scene for the session's current preset (a new generation)."""
        pl = self.plotter
        self._clear_widgets()
        for a in self._mirror_actors:
            pl.remove_actor(a, render=False)
        self._mirror_actors = []
        pl.clear_actors() if hasattr(pl, "clear_actors") else pl.clear()
        topo, display, layout = frame.topology, frame.display, frame.layout
        positions = np.asarray(frame.positions, np.float32)
        colours = _rgb8(frame.colours)
        extra: list[pv.PolyData] = []
        if display == "lines":
            pts, quads = _presets.line_display_mesh(frame.weights, topo, layout)
            n = len(positions)
            segs = np.hstack([np.full((n, 1), 2), np.arange(n)[:, None], np.arange(n, 2 * n)[:, None]]).ravel()
            # one dataset, two actors: the quads between neighbouring lines, and the lines drawn over them
            # the quads between neighbouring lines, and the lines drawn over them (each actor has its own
            # dataset; `apply` updates both. Names: pyvista drops "clay-*" actors when "clay" is added)
            mesh = pv.PolyData(pts, faces=cell_array(quads))
            mesh.point_data["rgb"] = np.concatenate([colours, colours])
            pl.add_mesh(mesh, scalars="rgb", rgb=True, opacity=0.8, show_edges=False, name="clay",
                        render=False)
            lines_mesh = pv.PolyData(pts, lines=segs)
            lines_mesh.point_data["rgb"] = mesh.point_data["rgb"]
            pl.add_mesh(lines_mesh, scalars="rgb", rgb=True, line_width=2, name="strokes", render=False)
            extra = [lines_mesh]
        elif display == "points" or not topo.faces:
            edges = np.asarray(topo.edges, np.int64).reshape(-1, 2)
            lines = np.hstack([np.full((len(edges), 1), 2), edges]).ravel() if len(edges) else None
            mesh = pv.PolyData(positions)
            mesh.point_data["rgb"] = colours
            pl.add_mesh(mesh, scalars="rgb", rgb=True, style="points", point_size=5, render_points_as_spheres=True,
                        name="clay", render=False)
            if lines is not None:
                edges_mesh = pv.PolyData(positions, lines=lines)
                edges_mesh.point_data["rgb"] = colours
                pl.add_mesh(edges_mesh, scalars="rgb", rgb=True, line_width=1, opacity=0.5, name="synapses",
                            render=False)
                extra = [edges_mesh]
        else:
            mesh = pv.PolyData(positions, faces=cell_array(topo.faces))
            mesh.point_data["rgb"] = colours
            pl.add_mesh(mesh, scalars="rgb", rgb=True, show_edges=True, edge_color=(0.35, 0.35, 0.4),
                        line_width=0.5, smooth_shading=False, name="clay", render=False)
        self._mesh = mesh
        self._meshes = [mesh, *extra]
        everything = np.concatenate([positions, np.asarray(frame.effective_positions, np.float32)])
        span = float(np.linalg.norm(everything.max(axis=0) - everything.min(axis=0))) or 1.0
        self._radius = 0.035 * span
        self._generation = frame.generation
        self._n_controls = -1
        self._sync_controls(frame)
        self._frame_camera(everything)
        self.frame = frame

    def _frame_camera(self, points: np.ndarray) -> None:
        centre = (points.max(axis=0) + points.min(axis=0)) / 2.0
        span = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0))) or 1.0
        direction = np.array([0.55, -1.0, 0.55])
        direction /= np.linalg.norm(direction)
        cam = self.plotter.camera
        cam.focal_point = tuple(centre)
        cam.position = tuple(centre + direction * span * 1.6)
        cam.up = (0.0, 0.0, 1.0)
        self.plotter.reset_camera_clipping_range()

    def _clear_widgets(self) -> None:
        for w in self.widgets:
            w.RemoveAllObservers()
            w.Off()
        self.widgets = []
        self.dragging = None

    def _make_widget(self, index: int, centre, colour) -> vtkSphereWidget:
        w = vtkSphereWidget()
        w.SetInteractor(self.plotter.iren.interactor)
        w.SetCurrentRenderer(self.plotter.renderer)
        w.SetRepresentationToSurface()
        w.SetThetaResolution(24)
        w.SetPhiResolution(16)
        w.SetRadius(self._radius)
        w.SetCenter(*[float(x) for x in centre])
        w.TranslationOn()
        w.ScaleOff()
        w.GetSphereProperty().SetColor(*[float(c) for c in colour])
        w.GetSphereProperty().SetSpecular(0.4)
        w.GetSelectedSphereProperty().SetColor(*SELECTED)
        w.AddObserver("StartInteractionEvent", lambda obj, _e, i=index: self._drag_start(i))
        w.AddObserver("InteractionEvent", lambda obj, _e, i=index: self._drag_move(i, obj))
        w.AddObserver("EndInteractionEvent", lambda obj, _e, i=index: self._drag_end(i, obj))
        w.On()
        return w

    def _sync_controls(self, frame: Frame) -> None:
        """Widgets for the originals, plain spheres for the mirrored copies; rebuilt when the count changes."""
        k = frame.n_controls
        k_eff = len(frame.effective_positions)
        pl = self.plotter
        own, eff = control_colours(frame, frame.layout.colour_space != "none")
        if k != self._n_controls or len(self._mirror_actors) != k_eff - k:
            self._clear_widgets()
            for a in self._mirror_actors:
                pl.remove_actor(a, render=False)
            self._mirror_actors = []
            self.widgets = [self._make_widget(i, frame.control_positions[i], own[i]) for i in range(k)]
            sphere = pv.Sphere(radius=self._radius, theta_resolution=20, phi_resolution=14)
            for j in range(k, k_eff):
                actor = pl.add_mesh(sphere, color=tuple(float(c) for c in eff[j]), opacity=0.6,
                                    name=f"mirror-{j}", render=False, pickable=False)
                actor.position = tuple(float(x) for x in frame.effective_positions[j])
                self._mirror_actors.append(actor)
            self._n_controls = k
            self._control_colours = np.array(eff)
            return
        for i, w in enumerate(self.widgets):
            if i != self.dragging:
                w.SetCenter(*[float(x) for x in frame.control_positions[i]])
        for j, actor in enumerate(self._mirror_actors, start=k):
            actor.position = tuple(float(x) for x in frame.effective_positions[j])
        if self._control_colours is None or not np.array_equal(self._control_colours, eff):
            for i, w in enumerate(self.widgets):
                w.GetSphereProperty().SetColor(*[float(c) for c in own[i]])
            for j, actor in enumerate(self._mirror_actors, start=k):
                actor.prop.color = tuple(float(c) for c in eff[j])
            self._control_colours = np.array(eff)

    # -- frames ---------------------------------------------------------------------------------------------------
    def apply(self, frame: Frame) -> bool:
        """Show `frame`; returns True when the scene was rebuilt (new preset: the camera was reset)."""
        if frame.generation != self._generation or self._mesh is None:
            self.build(frame)
            return True
        colours = _rgb8(frame.colours)
        if frame.display == "lines" and frame.layout.direction:
            pts, _ = _presets.line_display_mesh(frame.weights, frame.topology, frame.layout)
            colours = np.concatenate([colours, colours])
        else:
            pts = np.asarray(frame.positions, np.float32)
        for mesh in self._meshes:
            mesh.points = pts
            mesh.point_data["rgb"] = colours
        self._sync_controls(frame)
        self.frame = frame
        # the image stream re-renders only when the render window's MTime moves past its last image
        self.plotter.render_window.Modified()
        return False

    # -- dragging -------------------------------------------------------------------------------------------------
    def _drag_start(self, index: int) -> None:
        self.dragging = index
        if self.on_drag is not None:
            self.on_drag(index)

    def _drag_move(self, index: int, widget) -> None:
        self.drag_moves += 1
        centre = widget.GetCenter()
        try:
            self.session.move_control(index, centre)
        except (ValueError, RuntimeError):  # the control went away meanwhile (removed, new preset)
            pass

    def _drag_end(self, index: int, widget) -> None:
        self._drag_move(index, widget)
        self.dragging = None
        if self.on_drag is not None:
            self.on_drag(None)

    def cancel_drag(self) -> None:
        """End a drag whose client went away: release the widget as a button release would."""
        if self.dragging is None:
            return
        iren = self.plotter.iren.interactor
        iren.InvokeEvent("LeftButtonReleaseEvent")
        if self.dragging is not None:  # the widget did not take the release: end it by hand
            index = self.dragging
            w = self.widgets[index] if index < len(self.widgets) else None
            if w is not None:
                w.Off()
                w.On()
            self.dragging = None
            if self.on_drag is not None:
                self.on_drag(None)

    # -- geometry for tests -------------------------------------------------------------------------------------
    def screen_positions(self, points) -> list[list[float]]:
        """Display coordinates (x right, y down, in render-window pixels) of world points."""
        ren = self.plotter.renderer
        h = self.plotter.render_window.GetSize()[1]
        out = []
        for p in np.asarray(points, np.float64).reshape(-1, 3):
            ren.SetWorldPoint(float(p[0]), float(p[1]), float(p[2]), 1.0)
            ren.WorldToDisplay()
            x, y, _z = ren.GetDisplayPoint()
            out.append([float(x), float(h - y)])
        return out

    def describe(self) -> dict:
        """Widget centres and their screen positions (for the debug route)."""
        centres = [list(w.GetCenter()) for w in self.widgets]
        return {
            "window_size": list(self.plotter.render_window.GetSize()),
            "widget_centres": centres,
            "widget_screen": self.screen_positions(centres) if centres else [],
            "radius": self._radius,
            "dragging": self.dragging,
            "drag_moves": self.drag_moves,
            "generation": self._generation,
            "frame_seq": self.frame.seq if self.frame is not None else None,
        }
