"""Checks a report figure must pass: data inside the axes, every axis labelled, units named.

Walks a matplotlib Figure's axes and what is drawn on them (lines, patches, collections) in
data coordinates. Lines drawn across the axes (``axhline``/``axvline``, whose transform is
partly in axes coordinates) mark a reference, not data, and are left out of the limits
check; so are annotations.
"""

from __future__ import annotations

import re
from collections.abc import Iterable

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import Collection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

#: A unit in brackets at the end of a label: "time [s]", "density of f_n [1/Hz]".
UNIT = re.compile(r"\[[^\]]+\]\s*$")


def _data_points(ax: Axes) -> np.ndarray:
    """Every finite (x, y) the axes draw in data coordinates."""
    chunks: list[np.ndarray] = []
    for line in ax.get_lines():
        if isinstance(line, Line2D) and line.get_transform() == ax.transData:
            xy = np.column_stack([line.get_xdata(orig=False), line.get_ydata(orig=False)])
            chunks.append(np.asarray(xy, dtype=float))
    for patch in ax.patches:
        if isinstance(patch, Patch) and patch.get_transform().contains_branch(ax.transData):
            box = patch.get_path().get_extents(patch.get_patch_transform())
            chunks.append(np.array([[box.x0, box.y0], [box.x1, box.y1]]))
    for coll in ax.collections:
        if isinstance(coll, Collection) and coll.get_transform() == ax.transData:
            for path in coll.get_paths():
                chunks.append(np.asarray(path.vertices, dtype=float))
        if isinstance(coll, Collection) and coll.get_offset_transform() == ax.transData:
            offsets = np.asarray(coll.get_offsets(), dtype=float)
            if offsets.size:
                chunks.append(offsets.reshape(-1, 2))
    if not chunks:
        return np.empty((0, 2))
    pts = np.vstack(chunks)
    return pts[np.all(np.isfinite(pts), axis=1)]


def _shared_label(ax: Axes, axis: str) -> str:
    """The label of an axis shared with other panels (the one panel that shows it)."""
    group = ax.get_shared_x_axes() if axis == "x" else ax.get_shared_y_axes()
    for other in group.get_siblings(ax):
        label = other.get_xlabel() if axis == "x" else other.get_ylabel()
        if label.strip():
            return str(label)
    return ""


def visible_axes(fig: Figure) -> list[Axes]:
    """Axes that show something (panels switched off and colour bars left out)."""
    return [ax for ax in fig.axes if ax.axison and ax.get_label() != "<colorbar>"]


def figure_problems(
    fig: Figure,
    *,
    dimensionless: Iterable[str] = (),
    clipped_x: bool = False,
) -> list[str]:
    """What is wrong with a figure, one sentence per problem (empty when it passes).

    Parameters
    ----------
    fig : Figure
    dimensionless : iterable of str
        Axis labels that name a pure number and so carry no unit (e.g. "damping ratio").
    clipped_x : bool
        The figure zooms into a window of its x data on purpose (a time window).
    """
    pure = set(dimensionless)
    problems: list[str] = []
    fig.canvas.draw()  # limits of constrained and autoscaled axes are final only once drawn
    for i, ax in enumerate(visible_axes(fig)):
        where = f"axes {i} ({ax.get_title() or 'untitled'})"
        for axis, label in (("x", ax.get_xlabel()), ("y", ax.get_ylabel())):
            if not label.strip():
                label = _shared_label(ax, axis)
            if not label.strip():
                problems.append(f"{where}: no {axis} label")
            elif not UNIT.search(label) and label not in pure:
                problems.append(f"{where}: {axis} label {label!r} names no unit")
        pts = _data_points(ax)
        if not pts.size:
            continue
        (x0, x1), (y0, y1) = sorted(ax.get_xlim()), sorted(ax.get_ylim())
        # Half a part in a thousand of the span: room for the rounding of drawn vertices.
        tx, ty = 5e-4 * (x1 - x0), 5e-4 * (y1 - y0)
        if not clipped_x and (pts[:, 0].min() < x0 - tx or pts[:, 0].max() > x1 + tx):
            problems.append(f"{where}: x limits {x0:g}-{x1:g} cut the data")
        if pts[:, 1].min() < y0 - ty or pts[:, 1].max() > y1 + ty:
            problems.append(
                f"{where}: y limits {y0:g}-{y1:g} cut the data "
                f"({pts[:, 1].min():g}-{pts[:, 1].max():g})"
            )
    return problems
