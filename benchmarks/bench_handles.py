"""Handles (issue 34, item 1): the candidate rules of modelling by hand against the issue's figures, in float64 numpy.

Every rule runs in tests/reference_handles.py's `HandleSom` (a `Rule`; the defaults are the chosen rule), the
baseline `carry` in tests/reference.py's `ReferenceSom` (the engine's rule of 2026-11-25). A kept shape's schedule:
S 1000, reach 0.3, smoothing 0 unless the row says; a drag is 8 frames of set_controls + 10 cycles, then the
release and the rest of the run; a typed move is one set_controls and the run. Sizes are the start's bounding
diagonal. The figures (columns):

  vase     the seven-ring script under 16-fold radial symmetry about z: seven rings of controls (radius 0.5) on the
           start, dragged one after the other (bottom first) to a vase profile within z -1.35 .. 1.45, from a tube
           (32 x 13, r 1, z -1 .. 1) and from the sphere preset (UV, 482 nodes). `z` the clay's z range at the end
           (both starts); `out` the farthest any node ever stood outside the box of the start and every place of
           the controls grown by the largest radius (share of the size; target 0); `gap` the 90th percentile of
           the controls' distances to the clay's surface at the end (share of the size; not a target: a later ring
           moves clay an earlier one placed)
  push     a control on the sphere's top pole, radius a quarter of the size, typed to z -0.6 (one move) on the
           UV sphere of 64 x 31 (1,986 nodes) and on the sphere preset refined once (1,922): the control's distance
           to the surface (target <= 3% of the size), the largest dihedral angle in degrees (target <= 45), the
           volume after over before (target >= 0.5), the far half's move (p90, share of the size: the bottom
           stays); `482` the largest angle on the unrefined preset (no target:
           four edges per radius cannot turn a 1.6-deep hole's rim under 45 degrees)
  flare    a ring (one control and its 15 copies, radius 0.5) dragged out by 0.4 on a tube of 64 x 25 (edges about
           0.09): in its middle and at its open end (a lip): the largest gap (target: reached, <= 1% of the size),
           the largest dihedral angle (target <= 35), and `dip` the share of the flare the ring's nodes between two
           copies lack (scallops; no target, 0 is a round ring); `32` the largest angle on the 32 x 13 tube (no
           target: a 0.4 ridge of half-width 0.5 turns 4 x 0.4 x 0.17 / 0.25 = 1.1 rad an edge there)
  far      each of the sphere preset's six controls (radius a quarter of the size) dragged out by 30% of the size:
           the largest 90th percentile of the far half's move (metrics.far_half_moved; target <= 2%), and the
           largest dihedral angle of the six pulls (no target: a 1.04 pull of a radius-0.87 patch is a horn whose
           tip turns 4 x 1.04 x 0.2 / 0.87^2 = 1.1 rad an edge on this mesh)
  s        seconds for the row

Then `volume`: smoothing alone (no control, the whole schedule from s = 0) at strength 0.1, 0.3 and 0.7 on the
UV sphere (482), an icosphere (642), a torus (768) and the trained car (602): the largest |volume after / before - 1|
for Taubin's pair alone (pass band 0.015, the engine's today), with the volume step (the chosen rule), and the
paper's Laplacian.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_handles.py                  # the table (a few minutes)
    PYTHONPATH=. .venv/bin/python benchmarks/bench_handles.py --rows carry     # the engine's rule (slow: dense tables)
    PYTHONPATH=. .venv/bin/python benchmarks/bench_handles.py --rows chosen carry --pictures docs/handles

Pictures need VTK off-screen (VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow on a headless machine).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from reference import ReferenceSom, edges_from_faces  # noqa: E402
from reference_handles import HandleSom, Rule  # noqa: E402

from somwidget.backend import metrics, presets  # noqa: E402
from somwidget.backend.refine import subdivide  # noqa: E402
from somwidget.backend.schedule import TABLE_KEYS  # noqa: E402
from somwidget.backend.symmetry import Symmetry  # noqa: E402

RADIAL = Symmetry.radial(16, 2).maps(3)
#: The vase profile, (radius, z) of each ring's control, bottom first.
VASE = [(0.6, -1.35), (0.9, -1.0), (1.05, -0.45), (0.9, 0.15), (0.45, 0.75), (0.32, 1.1), (0.5, 1.45)]
VASE_RADIUS = 0.5


# -- meshes: (faces, points float64)
def uv_sphere(n_lon=32, n_rings=15):
    f, p = presets.uv_ellipsoid(n_lon, n_rings)
    return [tuple(x) for x in f], p.astype(np.float64)


def refined_sphere():
    f, p = subdivide(*uv_sphere())
    return [tuple(int(i) for i in x) for x in f], np.asarray(p, np.float64)


def tube(n_around=32, rings=13):
    """An open tube of radius 1 around z, z -1 .. 1: ring r's node j at r * n_around + j."""
    z = np.linspace(-1.0, 1.0, rings)
    t = 2 * np.pi * np.arange(n_around) / n_around
    p = np.stack(np.broadcast_arrays(np.cos(t)[None], np.sin(t)[None], z[:, None]), -1).reshape(-1, 3)
    f = [(r * n_around + j, r * n_around + (j + 1) % n_around, (r + 1) * n_around + (j + 1) % n_around,
          (r + 1) * n_around + j) for r in range(rings - 1) for j in range(n_around)]
    return f, p.astype(np.float64)


def icosphere():
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=3)
    return [tuple(x) for x in m.faces], np.asarray(m.vertices, np.float64)


def torus():
    f, p = presets.torus(48, 16, 1.0, 0.35)
    return [tuple(x) for x in f], p.astype(np.float64)


def trained_car():
    c = presets.car()
    som = HandleSom(c.weights, c.controls, faces=c.topology.faces, maps=Symmetry.mirror(1).on((0, 1, 2)).maps(5),
                    **{key: getattr(c, key) for key in TABLE_KEYS}, smoothing_rule="laplacian")
    som.train_from_start()
    return [tuple(int(i) for i in f) for f in c.topology.faces], som.W


# -- the baseline, driven like a HandleSom
class Carry:
    """The engine's `carry` rule (reference.py's shaping path) with HandleSom's drag and move."""

    def __init__(self, weights, controls, radii, faces, maps=None, smoothing=0.0):
        self.faces = faces
        self.ref = ReferenceSom(len(weights), edges_from_faces(faces), weights, controls, iterations=1000, reach=0.3,
                                radii=radii, group_maps=maps, smoothing=smoothing, smoothing_rule="taubin")
        self.ref.iteration = 1000
        self.maps = np.eye(3)[None] if maps is None else maps
        self.r = float(np.max(radii))
        start = np.asarray(weights, np.float64)
        self.lo, self.hi = start.min(axis=0), start.max(axis=0)
        self.size = metrics.bounding_diagonal(start)
        self.excess = 0.0
        self._seen(controls)

    @property
    def W(self):
        return self.ref.W

    @property
    def controls(self):
        return self.ref.controls

    def _seen(self, controls):
        m = np.einsum("gij,kj->kgi", self.maps, np.asarray(controls, np.float64)).reshape(-1, 3)
        self.lo, self.hi = np.minimum(self.lo, m.min(axis=0)), np.maximum(self.hi, m.max(axis=0))

    def _check(self):
        out = np.maximum(self.lo - self.r - self.W, self.W - self.hi - self.r).max()
        self.excess = max(self.excess, float(out))

    def move(self, c, place):
        new = self.controls.copy()
        new[c] = place
        self._seen(new)
        self.ref.set_controls(new)

    def step(self, n):
        self.ref.step(n)
        self._check()

    def train(self):
        while self.ref.iteration < self.ref.iterations:
            self.step(50)

    def drag(self, c, place, frames=8, frame_cycles=10, settle=True):
        start = self.controls[c].copy()
        for f in range(1, frames + 1):
            self.move(c, start + (np.asarray(place, np.float64) - start) * f / frames)
            self.step(frame_cycles)
        if settle:
            self.train()


def make(rule, points, controls, radii, faces, maps=None, smoothing=0.0):
    if rule == "carry":
        return Carry(points, controls, radii, faces, maps, smoothing)
    return HandleSom(points, controls, radii, faces=faces, maps=maps, smoothing=smoothing, rule=rule)


def gaps(som, faces, points) -> np.ndarray:
    return metrics.surface_distances(points, som.W[:, :3], faces)


def max_angle(W, faces) -> float:
    return float(np.nanmax(metrics.dihedral_angles(np.asarray(W)[:, :3], metrics.triangles_of(faces))))


# -- the figures
def vase(rule, start: str, smoothing=0.0, shots=None) -> dict:
    faces, p = tube() if start == "tube" else uv_sphere()
    size = metrics.bounding_diagonal(p)
    if start == "tube":
        ring_nodes = [r * 32 for r in range(0, 13, 2)]  # z -1, -2/3, ..., 1 at x = 1, y = 0
    else:
        ring_nodes = [1 + r * 32 for r in range(13, 0, -2)]  # polar angle 14/16 pi ... 2/16 pi
    controls = p[ring_nodes].copy()
    som = make(rule, p, controls, [VASE_RADIUS] * 7, faces, RADIAL, smoothing)
    for c, (rho, z) in enumerate(VASE):
        som.drag(c, (rho, 0.0, z))
    members = np.einsum("gij,kj->kgi", RADIAL, som.controls).reshape(-1, 3)
    if shots is not None:
        shots.append((f"vase_{start}", som.W, faces, members, f"vase from a {start}"))
    return dict(zlo=float(som.W[:, 2].min()), zhi=float(som.W[:, 2].max()), out=som.excess / size,
                gap=float(np.percentile(gaps(som, faces, members[::4]), 90)) / size, angle=max_angle(som.W, faces))


def push(rule, mesh: str, smoothing=0.0, shots=None) -> dict:
    faces, p = {"fine": lambda: uv_sphere(64, 31), "refined": refined_sphere, "coarse": uv_sphere}[mesh]()
    size = metrics.bounding_diagonal(p)
    som = make(rule, p, p[:1], [0.25 * size], faces, None, smoothing)
    target = np.array([0.0, 0.0, -0.6])
    som.move(0, target)
    som.train()
    if shots is not None:
        shots.append((f"push_{mesh}", som.W, faces, target[None], f"push to z -0.6 ({len(p)} nodes)"))
    return dict(gap=float(gaps(som, faces, target[None])[0]) / size, angle=max_angle(som.W, faces),
                volume=metrics.mesh_volume(som.W, faces) / metrics.mesh_volume(p, faces),
                far=metrics.far_half_moved(p, som.W, p[0]))


def flare(rule, where: str, fine: bool = True, smoothing=0.0, shots=None) -> dict:
    n_around, rings = (64, 25) if fine else (32, 13)
    faces, p = tube(n_around, rings)
    size = metrics.bounding_diagonal(p)
    ring = rings // 2 if where == "mid" else rings - 1
    c0 = p[ring * n_around].copy()
    som = make(rule, p, c0[None], [VASE_RADIUS], faces, RADIAL, smoothing)
    target = c0 + np.array([0.4, 0.0, 0.0])
    som.drag(0, target)
    members = np.einsum("gij,j->gi", RADIAL, target)
    if shots is not None:
        shots.append((f"flare_{where}", som.W, faces, members, f"ring flared 0.4 ({where})"))
    out = np.hypot(*som.W[ring * n_around:(ring + 1) * n_around, :2].T) - 1.0  # the ring's flare, node by node
    return dict(gap=float(gaps(som, faces, members).max()) / size, angle=max_angle(som.W, faces),
                dip=1.0 - float(out.min() / out.max()))


def far(rule, smoothing=0.0, shots=None) -> dict:
    sphere = presets.sphere_preset()
    faces = [tuple(int(i) for i in f) for f in sphere.topology.faces]
    p = sphere.weights.astype(np.float64)
    size = metrics.bounding_diagonal(p)
    worst, angle = 0.0, 0.0
    for c in range(len(sphere.controls)):
        controls = sphere.controls.astype(np.float64)
        som = make(rule, p, controls, [0.25 * size] * len(controls), faces, None, smoothing)
        d = controls[c] - p.mean(axis=0)
        target = controls[c] + 0.3 * size * d / np.linalg.norm(d)
        som.drag(c, target)
        worst = max(worst, metrics.far_half_moved(p, som.W, target))
        angle = max(angle, max_angle(som.W, faces))
        if shots is not None and c == 4:
            side = np.cross(d, (0.0, 0.0, 1.0)) / np.linalg.norm(d) + (0.0, 0.0, 0.4)
            shots.append(("pull", som.W, faces, som.controls, "a control pulled out 30%", side))
    return dict(far=worst, angle=angle)


ROWS = {
    "carry": ("carry: the engine's rule (2026-11-25)", "carry", 0.0),
    "literal": ("geodesic, quartic, sum, bound once at the grab", Rule(distance="geodesic", blend="sum", carry="grab"),
                0.0),
    "or": ("  ... blend or: mean D x (1 - prod(1 - w))", Rule(distance="geodesic", carry="grab"), 0.0),
    "steps": ("  ... bound again every step of r/4", Rule(distance="geodesic"), 0.0),
    "chosen": ("  ... straight distance in the ball: CHOSEN", Rule(), 0.0),
    "sum": ("chosen, blend sum: sum w D / max(1, sum w)", Rule(blend="sum"), 0.0),
    "cosine": ("chosen, falloff cosine", Rule(falloff="cosine"), 0.0),
    "spline": ("chosen, falloff spline (|f''| 4)", Rule(falloff="spline"), 0.0),
    "smootherstep": ("chosen, falloff smootherstep", Rule(falloff="smootherstep"), 0.0),
    "wendland": ("chosen, falloff Wendland C2", Rule(falloff="wendland"), 0.0),
    "edges": ("chosen, distance Dijkstra over edges", Rule(distance="edges"), 0.0),
    "hops": ("chosen, distance hops x edge", Rule(distance="hops"), 0.0),
    "schedule": ("chosen, bound nodes at alpha(s)", Rule(rate="schedule"), 0.0),
    "paper": ("chosen, others pull by the paper's rule", Rule(others="paper"), 0.0),
    "fit": ("chosen, radius widened for long pulls (0.4 rad)", Rule(fit=0.4), 0.0),
    "smooth": ("chosen, Taubin smoothing 0.3 + volume", Rule(), 0.3),
}


def row(rule, smoothing, shots=None) -> dict:
    out = {}
    for start in ("tube", "sphere"):
        out[f"vase_{start}"] = vase(rule, start, smoothing, shots)
    for mesh in ("fine", "refined", "coarse"):
        out[f"push_{mesh}"] = push(rule, mesh, smoothing, shots if mesh == "fine" else None)
    out["flare_mid"] = flare(rule, "mid", True, smoothing, shots)
    out["flare_lip"] = flare(rule, "lip", True, smoothing, shots)
    out["flare_coarse"] = flare(rule, "mid", False, smoothing)
    out["far"] = far(rule, smoothing, shots)
    return out


def volume_table() -> list[str]:
    meshes = {"UV sphere 482": uv_sphere(), "icosphere 642": icosphere(), "torus 768": torus(),
              "car 602 (trained)": trained_car()}
    kinds = {"Taubin 0.015 alone": ("taubin", Rule(volume=False)), "Taubin + volume step (chosen)": ("taubin", Rule()),
             "paper's Laplacian": ("laplacian", Rule())}
    lines = [f"{'volume drift, worst of strength 0.1 / 0.3 / 0.7':48s}" + "".join(f"{m:>20s}" for m in meshes)]
    for kind, (smoothing_rule, rule) in kinds.items():
        cells = []
        for faces, p in meshes.values():
            v0 = metrics.mesh_volume(p[:, :3], faces)
            worst = 0.0
            for lam in (0.1, 0.3, 0.7):
                som = HandleSom(p, np.zeros((0, p.shape[1])), faces=faces, smoothing=lam,
                                smoothing_rule=smoothing_rule, rule=rule)
                som.train_from_start()
                worst = max(worst, abs(metrics.mesh_volume(som.W[:, :3], faces) / v0 - 1.0))
            cells.append(f"{worst:20.2%}")
        lines.append(f"{kind:48s}" + "".join(cells))
    return lines


def picture(path: Path, W, faces, controls, title: str, direction=(0.55, -1.0, 0.75), size=(360, 300)) -> None:
    import pyvista as pv

    pv.OFF_SCREEN = True
    cells = np.concatenate([[len(f), *f] for f in faces]).astype(np.int64)
    mesh = pv.PolyData(np.asarray(W, np.float64)[:, :3], cells)
    plotter = pv.Plotter(off_screen=True, window_size=size)
    plotter.add_mesh(mesh, color="#c9b7a0", show_edges=True, edge_color="#7a6a58", line_width=0.4)
    for c in np.asarray(controls, np.float64).reshape(-1, 3):
        plotter.add_mesh(pv.Sphere(radius=0.04, center=c), color="#d04030")
    plotter.add_text(f"{title}  (max {max_angle(W, faces):.0f} deg)", font_size=8)
    lo, hi = mesh.bounds[::2], mesh.bounds[1::2]
    centre = (np.array(lo) + np.array(hi)) / 2
    span = float(np.linalg.norm(np.array(hi) - np.array(lo)))
    eye = centre + np.asarray(direction, np.float64) / np.linalg.norm(direction) * span * 1.9
    plotter.camera_position = [tuple(eye), tuple(centre), (0.0, 0.0, 1.0)]
    image = plotter.screenshot(None, return_img=True)
    plotter.close()
    from PIL import Image

    Image.fromarray(image).quantize(colors=128, dither=Image.Dither.NONE).save(path, optimize=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", nargs="+", choices=list(ROWS), default=[k for k in ROWS if k != "carry"],
                        help="rows to run (default: all but carry, whose reference takes several minutes)")
    parser.add_argument("--no-volume", action="store_true", help="skip the smoothing-alone volume table")
    parser.add_argument("--pictures", type=Path, help="save a PNG of each case of the rows asked here")
    args = parser.parse_args()
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    if args.pictures:
        args.pictures.mkdir(parents=True, exist_ok=True)
    head = (f"{'rule':46s} | {'vase tube: z, out, gap':24s} | {'vase sphere: z, out, gap':24s} | "
            f"{'push: gap, deg, vol, far / refined / 482':42s} | {'flare mid, lip: gap deg dip / 32':38s} | "
            "far, deg    | s")
    print(head)
    print("-" * len(head))
    for key in args.rows:
        label, rule, smoothing = ROWS[key]
        shots = [] if args.pictures else None
        t = time.time()
        f = row(rule, smoothing, shots)
        vt, vs = f["vase_tube"], f["vase_sphere"]
        pf, pr, pc = f["push_fine"], f["push_refined"], f["push_coarse"]
        fm, fl = f["flare_mid"], f["flare_lip"]
        print(f"{label:46s} | {vt['zlo']:5.2f}..{vt['zhi']:5.2f} {vt['out']:5.1%} {vt['gap']:4.1%} | "
              f"{vs['zlo']:5.2f}..{vs['zhi']:5.2f} {vs['out']:5.1%} {vs['gap']:4.1%} | "
              f"{pf['gap']:4.1%} {pf['angle']:4.1f} {pf['volume']:4.2f} {pf['far']:5.1%} / {pr['angle']:4.1f} / "
              f"{pc['angle']:3.0f} | "
              f"{fm['gap']:4.1%} {fm['angle']:4.1f} {fm['dip']:4.1%}, "
              f"{fl['gap']:4.1%} {fl['angle']:4.1f} {fl['dip']:4.1%} / {f['flare_coarse']['angle']:3.0f} | "
              f"{f['far']['far']:5.2%} {f['far']['angle']:3.0f} | {time.time() - t:3.0f}", flush=True)
        for name, W, faces, controls, title, *view in shots or []:
            picture(args.pictures / f"{key}_{name}.png", W, faces, controls, f"{key}: {title}", *view)
    if not args.no_volume:
        print()
        print("\n".join(volume_table()))


if __name__ == "__main__":
    main()
