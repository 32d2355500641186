"""Figures that tell whether the clay behaves like clay: size, gaps to the controls, spikes, mirror symmetry, and how
a trained shape follows one moved control (som.py, Restarts). numpy only; positions are (N, 3) float arrays."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .topology import Topology


def bounding_diagonal(positions) -> float:
    """The length of the diagonal of the axis-aligned bounding box: a shape's size."""
    p = np.asarray(positions, np.float64)
    return float(np.linalg.norm(p.max(axis=0) - p.min(axis=0))) if len(p) else 0.0


def nearest_distances(points, nodes) -> np.ndarray:
    """(len(points),) the distance from each point to its nearest node (in blocks: memory stays bounded)."""
    pts = np.asarray(points, np.float64)
    nds = np.asarray(nodes, np.float64)
    out = np.zeros(len(pts))
    if not len(pts) or not len(nds):
        return out
    block = max(1, 4_000_000 // len(nds))
    for i in range(0, len(pts), block):
        d = pts[i:i + block, None, :] - nds[None, :, :]
        out[i:i + block] = np.sqrt(np.einsum("kni,kni->kn", d, d).min(axis=1))
    return out


def spike_figures(positions, topology: Topology, nodes) -> np.ndarray:
    """For each of `nodes` (the winners): its distance to the mean of its one-ring over the median edge length. A
    smooth surface gives a small fraction of one; a node drawn out alone towards its control (a needle) several."""
    p = np.asarray(positions, np.float64)
    edges = np.asarray(topology.edges, np.int64).reshape(-1, 2)
    if not len(edges):
        return np.zeros(len(nodes))
    median_edge = float(np.median(np.linalg.norm(p[edges[:, 0]] - p[edges[:, 1]], axis=1))) or 1.0
    out = []
    for v in np.asarray(nodes, np.int64).tolist():
        ring = topology.neighbors[topology.offsets[v]: topology.offsets[v + 1]]
        out.append(np.linalg.norm(p[v] - p[ring].mean(axis=0)) / median_edge if len(ring) else 0.0)
    return np.asarray(out)


def mirror_map(positions, dim: int = 1) -> np.ndarray:
    """For each node, the node nearest its mirror image (coordinate `dim` negated): the pairing of a symmetric
    start mesh, against which a trained shape's symmetry is measured."""
    p = np.asarray(positions, np.float64)
    image = p.copy()
    image[:, dim] *= -1.0
    out = np.empty(len(p), np.int64)
    block = max(1, 4_000_000 // max(1, len(p)))
    for i in range(0, len(p), block):
        d = image[i:i + block, None, :] - p[None, :, :]
        out[i:i + block] = np.einsum("kni,kni->kn", d, d).argmin(axis=1)
    return out


def symmetry_error(positions, pairing: np.ndarray, dim: int = 1) -> float:
    """The largest distance between a node's mirror image and its partner's position, over the shape's size."""
    p = np.asarray(positions, np.float64)
    image = p.copy()
    image[:, dim] *= -1.0
    size = bounding_diagonal(p) or 1.0
    return float(np.linalg.norm(image - p[pairing], axis=1).max() / size)


def far_half_moved(before, after, target, mirrored_axes=()) -> float:
    """How far the half of the nodes farther from `target` (and from its mirror image, `mirrored_axes` of the
    position negated) moved from `before` to `after`: the 90th percentile, over the size of `before`."""
    before = np.asarray(before, np.float64)
    target = np.asarray(target, np.float64)
    near = np.linalg.norm(before - target, axis=1)
    if len(mirrored_axes):
        image = target.copy()
        image[list(mirrored_axes)] *= -1.0
        near = np.minimum(near, np.linalg.norm(before - image, axis=1))
    far = near > np.median(near)
    moved = np.linalg.norm(np.asarray(after, np.float64) - before, axis=1)
    return float(np.percentile(moved[far], 90)) / (bounding_diagonal(before) or 1.0)


@dataclass(frozen=True)
class FollowFigures:
    """How a trained shape followed one control moved by `share` of its size, run to s = S (all as shares of the
    size before the move): `least_size` the smallest bounding diagonal at any frame over the one before;
    `far_moved_p90` the 90th percentile of how far the half of the nodes farther from the moved control (and its
    mirror) moved; `gap` the distance from the moved control to its nearest node at the end; `spike` the largest
    spike figure of the winners at the end (median edge lengths)."""

    least_size: float
    far_moved_p90: float
    gap: float
    spike: float
    cycles: int


def follow(som, control: int, share: float = 0.05, direction=None, position_dims=(0, 1, 2),
           frame_cycles: int = 10) -> FollowFigures:
    """Move control `control` of a Som by `share` of the shape's size (along `direction`, default: away from the
    shape's centroid), then run the restarted schedule to s = S in frames of `frame_cycles` cycles, as the app does,
    measuring the size after every frame. The Som is left at the end of the run."""
    dims = list(position_dims)
    before = som.weights[:, dims].astype(np.float64)
    size = bounding_diagonal(before)
    controls = som.controls
    where = controls[control, dims].astype(np.float64)
    d = where - before.mean(axis=0) if direction is None else np.asarray(direction, np.float64)
    d = d / (np.linalg.norm(d) or 1.0)
    controls[control, dims] = (where + share * size * d).astype(np.float32)
    som.set_controls(controls)
    least, cycles = size, 0
    while som.iteration < som.iterations:
        cycles += som.step(frame_cycles)
        least = min(least, bounding_diagonal(som.weights[:, dims]))
    after = som.weights[:, dims].astype(np.float64)
    target = controls[control, dims].astype(np.float64)
    mirrored = [dims.index(m) for m in som.mirror if m in dims]
    return FollowFigures(
        least_size=least / size, far_moved_p90=far_half_moved(before, after, target, mirrored),
        gap=float(nearest_distances(target[None, :], after)[0]) / size,
        spike=float(spike_figures(after, som.topology, np.unique(som.winners())).max()), cycles=cycles)
