"""The posterior of (C, K) on its quadrature nodes, kept for fits over many records.

A population law fitted to point estimates uses one number per record and drops the records
that did not pass; a law fitted to every record's *likelihood* weighs a record that pins f_n
to 2 % against one that leaves it at 20 %, and uses both (docs/science.md 8). The exact grid
posterior (and the deck route's, which is one) holds that likelihood on its nodes, so an
identification keeps them:

- the nodes that hold all but a thousandth of the posterior mass, their posterior mass
  renormalised over them, and the share of the whole grid's mass they hold. At most
  :data:`MAX_NODES`: a wide posterior (a weak deck's, flat over much of the prior box)
  would need many more, so its grid is coarsened first, k x k cells merged into one node
  at their mass's centroid with the merged cell's edges, for the smallest k at which that
  many nodes suffice (:func:`node_posterior_from_grid`). A wide likelihood is then kept
  whole, at a coarser resolution, rather than cut to its highest part;
- the prior they were computed under: uniform over the prior box in (C, K), so within the
  box the likelihood is proportional to the mass (the cells are alike), and the cells'
  edges, since a node stands for its cell (:meth:`NodePosterior.modal_cell_variance`);
- each node's walk load factors BLF1-3 (those the population laws use) given its (C, K),
  mean and sd, computed at the node's own (C, K) (a load factor changes fast with C and K
  where the deck moves near the gait, so a node cannot borrow another point's). The sd is
  that of the walker's long-run mean at this crossing, the quantity a population law
  describes, not of the few steps recorded
  (:func:`~workbench.inference.core.load_factors.long_run_variance_of_mean`), with the load
  factors' spread over the node's cell added: the cell's variance of a function linear over
  it, its slopes along the cell's edges taken from the neighbouring nodes
  (:func:`cell_variance_from_neighbours`).

In the walker's own terms: a density uniform in (C, K) is, in (f_n, zeta), proportional to
``1 / |J|`` with ``J = d(f_n, zeta) / d(C, K)``; ``f_n = sqrt(K / M) / (2 pi)`` depends on K
alone and ``zeta = C / (2 sqrt(K M))`` on C linearly, so ``|J| = (f_n / (2 K)) / (2 sqrt(K
M))``. :meth:`NodePosterior.log_prior_modal` is ``-log |J|``: dividing it out of the node
masses leaves the likelihood of (f_n, zeta) at the nodes, whatever population density a
later fit multiplies in.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.special import logsumexp

from workbench.errors import UsageError
from workbench.inference.core.problem import StiffnessDampingPrior

__all__ = [
    "NODE_LOAD_FACTORS",
    "NODE_POSTERIOR_VERSION",
    "NodePosterior",
    "cell_variance_from_neighbours",
    "node_posterior_from_grid",
]

FloatArray = NDArray[np.float64]

#: Load factors kept per node: BLF1-3, those the population laws use.
NODE_LOAD_FACTORS = 3
#: Nodes a record keeps at most ...
MAX_NODES = 160
#: ... holding all but this much of the posterior's mass.
MASS_TAIL = 1e-3
#: The stored form's version. 2: every node's load factors at its own (C, K), their sd the
#: long-run mean's with the cell's spread (version 1, unnumbered, took the nearest force
#: node's and the realised steps' sd, too narrow for a population fit).
NODE_POSTERIOR_VERSION = 2
#: Significant digits the JSON keeps (as ``results.csv`` does).
_DIGITS = 10


def _rounded(values: Any) -> Any:
    return np.vectorize(lambda x: float(f"{x:.{_DIGITS}g}"), otypes=[float])(values).tolist()


@dataclass(frozen=True, eq=False)
class NodePosterior:
    """The posterior of (C, K) on the nodes that hold nearly all its mass (module docstring).

    Attributes
    ----------
    damping_ns_per_m, stiffness_n_per_m : ndarray, shape (B,)
        The nodes' C [N s/m] and K [N/m].
    weight : ndarray, shape (B,)
        Posterior mass of each node, renormalised over the nodes (sums to one).
    mass_held : float
        Share of the whole posterior's mass the nodes hold before renormalising.
    blf_mean, blf_sd : ndarray, shape (B, 3)
        The walk's mean load factors BLF1-3 given each node's (C, K), and the sd of the
        walker's long-run mean over the node's cell (module docstring; fewer columns where
        the model has fewer harmonics).
    prior : StiffnessDampingPrior
        The uniform prior box over (C, K) the posterior was computed under.
    mass_kg : float
        Body mass [kg].
    cell_edges : ndarray, shape (2, 2)
        Edge vectors of every node's cell as columns, in (C [N s/m], K [N/m]): a node
        stands for its cell, a parallelogram centred on it (NaN where unknown).
    kind : str
        ``"grid"``: the exact posterior's nodes, masses their cells'.
    """

    damping_ns_per_m: FloatArray
    stiffness_n_per_m: FloatArray
    weight: FloatArray
    mass_held: float
    blf_mean: FloatArray
    blf_sd: FloatArray
    prior: StiffnessDampingPrior
    mass_kg: float
    cell_edges: FloatArray
    kind: str = "grid"

    @property
    def natural_frequency_hz(self) -> FloatArray:
        """Natural frequency at every node [Hz]."""
        return np.sqrt(self.stiffness_n_per_m / self.mass_kg) / (2.0 * math.pi)

    @property
    def damping_ratio(self) -> FloatArray:
        """Damping ratio at every node."""
        return self.damping_ns_per_m / (2.0 * np.sqrt(self.stiffness_n_per_m * self.mass_kg))

    def log_prior_modal(self) -> FloatArray:
        """Log density of the uniform (C, K) prior in (f_n, zeta) at every node, up to a constant.

        ``-log |J|`` (module docstring).
        """
        k = self.stiffness_n_per_m
        jac = (self.natural_frequency_hz / (2.0 * k)) / (2.0 * np.sqrt(k * self.mass_kg))
        return np.asarray(-np.log(jac), dtype=np.float64)

    def modal_cell_variance(self) -> tuple[FloatArray, FloatArray]:
        """Variance of f_n and of zeta over every node's cell, (B,) each.

        A cell is uniform over its parallelogram, whose covariance in (C, K) is ``(e1 e1' +
        e2 e2') / 12``; mapped through the Jacobian at the node (``d f_n / d C = 0``, ``d f_n
        / d K = f_n / 2K``, ``d zeta / d C = zeta / C``, ``d zeta / d K = -zeta / 2K``). A
        fit that treats the node as a point would let a population sd narrower than a cell
        pick single nodes; with this spread it sees the cell.
        """
        e = np.asarray(self.cell_edges, dtype=np.float64)
        cov = (np.outer(e[:, 0], e[:, 0]) + np.outer(e[:, 1], e[:, 1])) / 12.0
        k = self.stiffness_n_per_m
        fn, zeta = self.natural_frequency_hz, self.damping_ratio
        df_dk = fn / (2.0 * k)
        dz_dc = 1.0 / (2.0 * np.sqrt(k * self.mass_kg))
        dz_dk = -zeta / (2.0 * k)
        var_fn = df_dk**2 * cov[1, 1]
        var_zeta = dz_dc**2 * cov[0, 0] + 2.0 * dz_dc * dz_dk * cov[0, 1] + dz_dk**2 * cov[1, 1]
        return np.asarray(var_fn, dtype=np.float64), np.asarray(var_zeta, dtype=np.float64)

    def load_factors_given(
        self, natural_frequency_hz: float, damping_ratio: float
    ) -> tuple[FloatArray, FloatArray]:
        """Mean and sd of the load factors BLF1-3 given the walker's f_n and zeta.

        Every node is weighted by its likelihood (its mass with the prior divided out) times
        the density of the given (f_n, zeta) over its cell (a normal with the cell's spread,
        :meth:`modal_cell_variance`), and the nodes' load factors are mixed with those
        weights (law of total variance). What a population fit reads from the record once
        the laws of f_n and zeta pin its node; with the true values, a check of the stored
        load factors against a simulation's. Like the fit, it mixes the neighbouring nodes
        whose cells the given values fall near, and each node's sd already holds its own
        cell's spread, so the sd is wider than the load factor's at that exact point: a
        check that it is not too narrow, not that it is not too wide.

        Returns
        -------
        mean, sd : ndarray, shape (n,)
        """
        var_fn, var_zeta = self.modal_cell_variance()
        with np.errstate(divide="ignore"):
            log_w = (
                np.log(self.weight)
                - self.log_prior_modal()
                - 0.5 * (self.natural_frequency_hz - natural_frequency_hz) ** 2 / var_fn
                - 0.5 * np.log(var_fn)
                - 0.5 * (self.damping_ratio - damping_ratio) ** 2 / var_zeta
                - 0.5 * np.log(var_zeta)
            )
        w = np.exp(log_w - logsumexp(log_w))
        mean = w @ self.blf_mean
        var = w @ self.blf_sd**2 + w @ (self.blf_mean - mean) ** 2
        return np.asarray(mean, dtype=np.float64), np.sqrt(np.maximum(var, 0.0))

    def to_json(self) -> dict[str, Any]:
        """Return a JSON-able dict (numbers to ten significant digits)."""
        return {
            "version": NODE_POSTERIOR_VERSION,
            "kind": self.kind,
            "prior": {
                "kind": "uniform",
                "damping_ns_per_m": list(self.prior.damping_ns_per_m),
                "stiffness_n_per_m": list(self.prior.stiffness_n_per_m),
            },
            "mass_kg": float(self.mass_kg),
            "mass_held": float(f"{self.mass_held:.{_DIGITS}g}"),
            "cell_edges": _rounded(self.cell_edges),
            "nodes": {
                "damping_ns_per_m": _rounded(self.damping_ns_per_m),
                "stiffness_n_per_m": _rounded(self.stiffness_n_per_m),
                "weight": _rounded(self.weight),
                "blf_mean": _rounded(self.blf_mean),
                "blf_sd": _rounded(self.blf_sd),
            },
        }

    @classmethod
    def from_json(cls, obj: Any, where: str) -> NodePosterior:
        """Read :meth:`to_json`'s dict back; a malformed one is a UsageError naming ``where``.

        Parameters
        ----------
        obj : dict
            The stored posterior.
        where : str
            What the dict came from (a file and key), for the error's sentence.
        """
        fix = "identify the record again with this version (its batch into a new folder)"
        if isinstance(obj, dict) and obj.get("version") != NODE_POSTERIOR_VERSION:
            raise UsageError(
                f"{where}: the stored posterior is of form {obj.get('version', 1)} and this "
                f"version reads form {NODE_POSTERIOR_VERSION} (form 1's load-factor sds are "
                f"too narrow for a population fit); {fix}"
            )
        try:
            nodes = obj["nodes"]
            prior = obj["prior"]
            c = np.asarray(nodes["damping_ns_per_m"], dtype=np.float64)
            k = np.asarray(nodes["stiffness_n_per_m"], dtype=np.float64)
            w = np.asarray(nodes["weight"], dtype=np.float64)
            blf_mean = np.asarray(nodes["blf_mean"], dtype=np.float64)
            blf_sd = np.asarray(nodes["blf_sd"], dtype=np.float64)
            box = StiffnessDampingPrior(
                tuple(prior["damping_ns_per_m"]),
                tuple(prior["stiffness_n_per_m"]),
            )
            mass_kg = float(obj["mass_kg"])
            held = float(obj["mass_held"])
            edges = np.asarray(obj["cell_edges"], dtype=np.float64)
            kind = str(obj.get("kind", "grid"))
        except (KeyError, TypeError, ValueError, UsageError) as err:
            raise UsageError(f"{where}: the stored posterior is malformed ({err}); {fix}") from None
        b = c.shape
        shapes_ok = (
            c.ndim == 1
            and c.size > 0
            and k.shape == b
            and w.shape == b
            and blf_mean.ndim == 2
            and blf_mean.shape[0] == c.size
            and blf_sd.shape == blf_mean.shape
            and edges.shape == (2, 2)
        )
        if not shapes_ok:
            raise UsageError(
                f"{where}: the stored posterior's node arrays do not have one entry per node; {fix}"
            )
        finite = all(np.all(np.isfinite(a)) for a in (c, k, w, blf_mean, blf_sd, edges))
        if not finite or np.any(w < 0) or w.sum() <= 0 or np.any(k <= 0) or mass_kg <= 0:
            raise UsageError(
                f"{where}: the stored posterior holds non-finite or negative numbers; {fix}"
            )
        return cls(c, k, w / w.sum(), held, blf_mean, blf_sd, box, mass_kg, edges, kind)


def cell_variance_from_neighbours(
    keys: NDArray[np.int64], points: FloatArray, edges: FloatArray, values: FloatArray
) -> FloatArray:
    """Variance over each node's cell of quantities linear over it, from the neighbouring nodes.

    A cell is the parallelogram spanned by ``edges``, and a point in it is ``x + E u`` with
    ``u`` uniform on (-1/2, 1/2)^2; a quantity linear over the cell, ``f(x) + h . u``, has
    variance ``(h_1^2 + h_2^2) / 12`` there. ``h`` (the change along each edge) is fitted by
    least squares to the differences to the node's kept lattice neighbours (one step along
    either edge), their offsets in edge units, since a merged node sits at its mass's
    centroid rather than its cell's centre. Exact for a linear quantity where the neighbours
    span both edges; with neighbours along one edge only, the change along the other is
    taken as zero (the least-squares minimum norm); a node with no kept neighbour (a
    posterior one cell wide holds nearly all its mass there) gets none. A curved quantity
    breaks the linear reading: at an extremum between two neighbours the central change
    is near zero, and where neighbours sit off a straight line (merged centroids do, by up
    to half a cell) curvature can be read as a steep change along the other edge.

    Parameters
    ----------
    keys : ndarray of int, shape (B, 2)
        Every node's cell on the lattice (unit steps along the edges).
    points : ndarray, shape (B, 2)
        The nodes' (C [N s/m], K [N/m]).
    edges : ndarray, shape (2, 2)
        The cells' edge vectors as columns, in (C, K).
    values : ndarray, shape (B, n)
        The quantities at the nodes.

    Returns
    -------
    ndarray, shape (B, n)
    """
    keys = np.asarray(keys, dtype=np.int64)
    v = np.asarray(values, dtype=np.float64)
    u = np.asarray(points, dtype=np.float64) @ np.linalg.inv(np.asarray(edges, dtype=np.float64)).T
    where = {(int(a), int(b)): i for i, (a, b) in enumerate(keys)}
    steps = ((1, 0), (-1, 0), (0, 1), (0, -1))
    out = np.zeros_like(v)
    for i, (a, b) in enumerate(keys):
        near = [where[key] for key in ((a + da, b + db) for da, db in steps) if key in where]
        if not near:
            continue
        # A direction the neighbours span by under a tenth of a cell is not fitted: the
        # centroids' jitter alone would give it a spurious slope.
        change, *_ = np.linalg.lstsq(u[near] - u[i], v[near] - v[i], rcond=0.1)
        out[i] = np.sum(change * change, axis=0) / 12.0
    return out


def node_posterior_from_grid(
    nodes: FloatArray,
    weights: FloatArray,
    cell_edges: FloatArray,
    load_factors: Callable[[FloatArray, FloatArray], tuple[FloatArray, FloatArray]],
    prior: StiffnessDampingPrior,
    mass_kg: float,
) -> NodePosterior:
    """Keep a grid posterior on at most :data:`MAX_NODES` nodes (module docstring).

    Parameters
    ----------
    nodes, weights : ndarray, shapes (M, 2), (M,)
        The grid's (C, K) nodes and posterior masses.
    cell_edges : ndarray, shape (2, 2)
        The grid's cell edges as columns.
    load_factors : callable
        ``load_factors(damping_ns_per_m, stiffness_n_per_m)`` -> ``(mean, variance)``, each of
        shape (B, n): the walk's load factors given (C, K) at the kept nodes, and the
        variance of the walker's long-run mean there (module docstring). The spread over
        each node's cell is added here.
    prior : StiffnessDampingPrior
    mass_kg : float

    Returns
    -------
    NodePosterior
    """
    w = np.asarray(weights, dtype=np.float64)
    w = w / w.sum()
    edges = np.asarray(cell_edges, dtype=np.float64)
    inverse = np.linalg.inv(edges)
    origin = nodes[int(np.argmax(w))]
    lattice = np.rint((nodes - origin) @ inverse.T).astype(np.int64)
    k = 1
    while True:
        block = np.floor_divide(lattice + k // 2, k)
        keys, which = np.unique(block, axis=0, return_inverse=True)
        which = which.reshape(-1)
        mass = np.bincount(which, weights=w, minlength=keys.shape[0])
        order = np.argsort(mass)[::-1]
        count = int(np.searchsorted(np.cumsum(mass[order]), 1.0 - MASS_TAIL)) + 1
        count = min(count, order.size)
        if count <= MAX_NODES or keys.shape[0] <= MAX_NODES:
            break
        k += 1
    kept = order[: min(count, MAX_NODES)]
    centroid = (
        np.stack(
            [np.bincount(which, weights=w * nodes[:, j], minlength=keys.shape[0]) for j in (0, 1)],
            axis=1,
        )[kept]
        / mass[kept, None]
    )
    blf_mean, blf_var = load_factors(centroid[:, 0].copy(), centroid[:, 1].copy())
    blf_mean = np.asarray(blf_mean, dtype=np.float64)
    blf_var = np.asarray(blf_var, dtype=np.float64) + cell_variance_from_neighbours(
        keys[kept], centroid, edges * k, blf_mean
    )
    held = float(mass[kept].sum())
    return NodePosterior(
        damping_ns_per_m=centroid[:, 0].copy(),
        stiffness_n_per_m=centroid[:, 1].copy(),
        weight=mass[kept] / held,
        mass_held=held,
        blf_mean=blf_mean,
        blf_sd=np.sqrt(np.maximum(blf_var, 0.0)),
        prior=prior,
        mass_kg=float(mass_kg),
        cell_edges=edges * k,
    )
