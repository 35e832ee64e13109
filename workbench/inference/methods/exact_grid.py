"""Frames and grids of the exact posterior: build, evaluate, check and re-grid.

A *frame* ``x = centre + A z``, ``z`` in ``[-1, 1]^2``, carries the lattice of cell centres
on which the exact method evaluates the likelihood (the prior box, the Laplace ellipse or a
rectangle around a previous grid's high region); a *grid* is a frame's in-box nodes with
their log-likelihood. The coverage and resolution checks and the re-gridding they trigger
are steps 3 and 4 of the construction described in :mod:`workbench.inference.methods.exact`.

Its own idea: the geometry of the quadrature, apart from the likelihood it is fed and the
posterior summaries made from it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from workbench.inference.methods.mode_search import _STENCIL, _sqrt_cov

FloatArray = NDArray[np.float64]

#: Minimum posterior sd in cells along every direction: 1.5 cells, i.e. at least 9 cells
#: across +-3 sd (the default frame, 23 nodes over +-7 sd, gives 1.65 and 10 across +-3 sd).
_MIN_SD_CELLS = 1.5


# -- frames and grids ------------------------------------------------------------------------
@dataclass(frozen=True)
class _Frame:
    centre: FloatArray
    matrix: FloatArray  # x = centre + matrix @ z, z in [-1, 1]^2
    n: int
    kind: str

    @property
    def edges(self) -> FloatArray:
        """Cell edge vectors as columns (x-space)."""
        return self.matrix * (2.0 / self.n)

    @property
    def cell_area(self) -> float:
        return abs(float(np.linalg.det(self.matrix))) * 4.0 / self.n**2

    @property
    def elliptic(self) -> bool:
        """Frames around a mode keep only the nodes inside the inscribed ellipse ``|z| <= 1``.

        The corners of the square hold 21 % of the nodes but, for a posterior the frame was
        fitted to, only density below ``exp(-log_threshold)``; the coverage check still
        catches a posterior that reaches them, and then the frame grows.
        """
        return self.kind == "laplace"

    def _keep_z(self, z: FloatArray) -> NDArray[np.bool_]:
        inside_square = np.all(np.abs(z) <= 1.0 + 1e-12, axis=-1)
        if not self.elliptic:
            return inside_square
        return inside_square & (np.sum(z * z, axis=-1) <= 1.0 + 1e-12)

    def z_of(self, points: FloatArray) -> FloatArray:
        z = np.linalg.solve(self.matrix, (np.atleast_2d(points) - self.centre).T).T
        return np.asarray(z, dtype=np.float64)

    def index_nodes(self) -> tuple[NDArray[np.int64], FloatArray]:
        """Lattice indices and (C, K) of the frame's nodes (ellipse or full square)."""
        i, j = np.meshgrid(np.arange(self.n), np.arange(self.n), indexing="ij")
        idx = np.column_stack([i.ravel(), j.ravel()])
        z = -1.0 + (2.0 * idx + 1.0) / self.n
        keep = self._keep_z(z)
        return idx[keep], self.centre + z[keep] @ self.matrix.T

    def keeps_index(self, idx: NDArray[np.int64]) -> NDArray[np.bool_]:
        """Whether lattice indices (possibly beyond 0..n-1) are nodes of the frame."""
        z = -1.0 + (2.0 * idx + 1.0) / self.n
        return self._keep_z(z)

    def contains(self, points: FloatArray) -> NDArray[np.bool_]:
        return self._keep_z(self.z_of(points))


def _box_frame(lo: FloatArray, hi: FloatArray, n: int, kind: str = "prior box") -> _Frame:
    return _Frame(0.5 * (lo + hi), np.diag(0.5 * (hi - lo)), n, kind)


def _inside(points: FloatArray, lo: FloatArray, hi: FloatArray) -> NDArray[np.bool_]:
    return np.all((points >= lo) & (points <= hi), axis=-1)


def _ellipse_frame(
    centre: FloatArray, cov: FloatArray, half_width_sd: float, n: int, kind: str
) -> _Frame:
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    w = np.maximum(w, 1e-300)
    return _Frame(np.asarray(centre, dtype=np.float64), (v * np.sqrt(w)) * half_width_sd, n, kind)


def _fit_frame(frame: _Frame, lo: FloatArray, hi: FloatArray, base_n: int) -> _Frame:
    """Choose the node count of a frame; a frame holding the whole box becomes the box.

    A frame the prior box clips keeps about as many nodes inside the box as an unclipped
    one has (at most twice the nodes per axis).
    """
    corners = np.array([[lo[0], lo[1]], [lo[0], hi[1]], [hi[0], lo[1]], [hi[0], hi[1]]])
    if frame.kind != "prior box" and np.all(frame.contains(corners)):
        return _box_frame(lo, hi, base_n)
    if frame.kind == "prior box":
        return frame
    _, nodes = _Frame(frame.centre, frame.matrix, base_n, frame.kind).index_nodes()
    fraction = max(float(np.mean(_inside(nodes, lo, hi))), 1e-9)
    n = int(min(2 * base_n, max(base_n, math.ceil(base_n / math.sqrt(fraction)))))
    return _Frame(frame.centre, frame.matrix, n, frame.kind)


@dataclass
class _Grid:
    frame: _Frame
    index: NDArray[np.int64]  # (M, 2) node indices of in-box nodes
    nodes: FloatArray  # (M, 2)
    loglik: FloatArray  # (M,)

    def weights(self) -> FloatArray:
        lp = self.loglik - np.max(self.loglik)
        w = np.exp(lp)
        return w / w.sum()


def _evaluate_frame(
    frame: _Frame, ev: Callable[[FloatArray], FloatArray], lo: FloatArray, hi: FloatArray
) -> _Grid:
    idx, nodes = frame.index_nodes()
    keep = _inside(nodes, lo, hi)
    if not np.any(keep):
        # The frame misses the box (cannot happen for frames built here); fall back to its
        # centre clipped into the box.
        nodes = np.clip(frame.centre, lo, hi)[None, :]
        idx = np.array([[frame.n // 2, frame.n // 2]])
        keep = np.array([True])
    return _Grid(frame, idx[keep], nodes[keep], ev(nodes[keep]))


def _region_frame(
    grid: _Grid,
    leaks: FloatArray,
    lo: FloatArray,
    hi: FloatArray,
    threshold: float,
    base_n: int,
    grow: float,
) -> _Frame:
    """Return a rectangle in the posterior's principal axes around the grid's high region.

    The rectangle spans the nodes within ``threshold`` of the maximum plus one cell, and
    reaches past any leak (lattice positions beyond the old frame next to high nodes) by
    ``grow`` times its width on that side; its nodes per axis give every principal sd at
    least 1.7 cells (between ``base_n`` and three times that). Unlike the Laplace ellipse it
    follows one-sided shapes: a posterior piled against a face or a corner of the box (then
    the rectangle's edges are parallel to the box faces).
    """
    w = grid.weights()
    mean, cov = _moments(grid.nodes, w)
    edges = grid.frame.edges
    # The cells' own spread keeps a posterior that sits inside one cell from giving a
    # zero-width frame.
    cov = cov + (np.outer(edges[:, 0], edges[:, 0]) + np.outer(edges[:, 1], edges[:, 1])) / 12.0
    high = grid.loglik > np.max(grid.loglik) - threshold
    cell_extent = np.sum(np.abs(edges), axis=1)
    near_face = (grid.nodes[high] - lo < cell_extent) | (hi - grid.nodes[high] < cell_extent)
    if np.any(near_face):
        # Piled against a face of the box: edges parallel to the faces, or a slightly
        # tilted edge would keep cutting through the densest part of the posterior.
        v = np.eye(2)
        evals = np.diag(cov).copy()
    else:
        evals, v = np.linalg.eigh(0.5 * (cov + cov.T))
    sd_axis = np.sqrt(np.maximum(evals, 1e-300))
    u = (grid.nodes[high] - mean) @ v
    # Two old cells of margin: the new lattice has other cells and another alignment, so a
    # node just past the old high region can be high on it; with one cell the refinement
    # chased such nodes from side to side on a posterior piled against a face (a leak on one
    # side, then on the other) and stopped uncovered, depending on the last bit of rounding.
    margin = 2.0 * np.sum(np.abs(v.T @ edges), axis=1)
    lo_u, hi_u = u.min(axis=0) - margin, u.max(axis=0) + margin
    if leaks.size:
        ul = (leaks - mean) @ v
        width = hi_u - lo_u
        lo_u = np.where(ul.min(axis=0) < lo_u, ul.min(axis=0) - grow * width, lo_u)
        hi_u = np.where(ul.max(axis=0) > hi_u, ul.max(axis=0) + grow * width, hi_u)
    if np.any(near_face):
        # Edges on the faces themselves: cells then tile the box up to the face and the
        # midpoint rule keeps its accuracy where the density is largest.
        lo_u = np.maximum(lo_u, lo - mean)
        hi_u = np.minimum(hi_u, hi - mean)
    half = 0.5 * (hi_u - lo_u)
    centre = mean + v @ (0.5 * (hi_u + lo_u))
    # Cells of c sd along each axis resolve the narrowest direction with 1.7 cells per sd
    # when c <= sqrt(1 - |rho|) / 1.7 (rho: correlation in the frame's axes, zero for the
    # principal axes).
    cov_v = v.T @ cov @ v
    rho = abs(float(cov_v[0, 1] / math.sqrt(max(cov_v[0, 0] * cov_v[1, 1], 1e-300))))
    n_axis = np.ceil(2.0 * half / (sd_axis * math.sqrt(max(1.0 - rho, 1e-6)) / 1.7))
    n = int(np.clip(np.max(n_axis), base_n, 3 * base_n))
    return _Frame(centre, v * half, n, "region")


def _coarse_start(
    grid: _Grid, lo: FloatArray, hi: FloatArray
) -> tuple[FloatArray, FloatArray, float | None]:
    """Start of the mode search from a coarse box grid: a free first Newton step.

    The 3 x 3 neighbourhood of the best node is a stencil already paid for; when it is
    complete and concave its quadratic gives the first Newton point and a scale, saving
    one likelihood call.
    """
    best = int(np.argmax(grid.loglik))
    x_best, f_best = grid.nodes[best], float(grid.loglik[best])
    cell = np.diag(np.diag(grid.frame.edges))
    i, j = grid.index[best]
    lookup = {(int(a), int(b)): n for n, (a, b) in enumerate(grid.index)}
    hood = [lookup.get((int(i + di), int(j + dj))) for di, dj in _STENCIL.astype(int)]
    if any(h is None for h in hood):
        return x_best, cell, f_best
    f = grid.loglik[np.array(hood)].reshape(3, 3)
    if not np.all(np.isfinite(f)):
        return x_best, cell, f_best
    g = np.array([(f[2, 1] - f[0, 1]) / 2, (f[1, 2] - f[1, 0]) / 2])
    h12 = (f[2, 2] - f[2, 0] - f[0, 2] + f[0, 0]) / 4
    h = np.array([[f[2, 1] - 2 * f[1, 1] + f[0, 1], h12], [h12, f[1, 2] - 2 * f[1, 1] + f[1, 0]]])
    if not np.all(np.linalg.eigvalsh(h) < 0):
        return x_best, cell, f_best
    z = -np.linalg.solve(h, g)
    if float(np.max(np.abs(z))) > 1.0:
        return x_best, cell, f_best  # the quadratic is not trustworthy that far out
    cov_z = np.linalg.inv(-h)
    return np.clip(x_best + cell @ z, lo, hi), cell @ _sqrt_cov(cov_z), None


def _moments(x: FloatArray, w: FloatArray) -> tuple[FloatArray, FloatArray]:
    mean = w @ x
    d = x - mean
    cov = (w[:, None] * d).T @ d
    return mean, 0.5 * (cov + cov.T)


def _check(
    grid: _Grid, lo: FloatArray, hi: FloatArray, threshold: float
) -> tuple[bool, bool, FloatArray]:
    """(covered, resolved, leaks) of a grid (exact module docstring, step 4).

    ``leaks`` holds the lattice positions just outside the frame (inside the box) next to
    high nodes.
    """
    frame = grid.frame
    top = float(np.max(grid.loglik))
    covered = True
    leaks: list[FloatArray] = []
    if frame.kind != "prior box":
        # A high node next to a lattice position the frame does not hold, where the prior
        # box continues, means the posterior's high region is cut off by the frame.
        high = grid.loglik > top - threshold
        edges = frame.edges
        for step in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            nb_idx = grid.index[high] + np.array(step)
            nb_x = grid.nodes[high] + edges @ np.array(step, dtype=np.float64)
            leak = ~frame.keeps_index(nb_idx) & _inside(nb_x, lo, hi)
            if np.any(leak):
                covered = False
                leaks.append(nb_x[leak])
    w = grid.weights()
    _, cov = _moments(grid.nodes, w)
    inv = np.linalg.inv(frame.edges)
    cov_cells = inv @ cov @ inv.T
    eig = np.linalg.eigvalsh(0.5 * (cov_cells + cov_cells.T))
    resolved = bool(math.sqrt(max(float(eig[0]), 0.0)) >= _MIN_SD_CELLS)
    return covered, resolved, (np.concatenate(leaks) if leaks else np.empty((0, 2)))
