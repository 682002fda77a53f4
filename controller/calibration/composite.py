"""One calibration problem over several measurement sets (any mix of measurement models).

`CompositeProblem` stacks the whitened rows of every `Block` (one instrument's readings, its
measurement model and noise) into one residual vector over one parameter vector:

    arm error model parameters (world/registration, D-H, tool)  +  each block's extras

It offers the attributes the solvers in solvers.py read (x0, free, free_idx, names, full,
residual_and_jacobian, whitening, nominal, rows, n_configs, sigma), so `lm`, `lse` and `ekf`
run on it unchanged. Its rows are already whitened (each row has unit noise), so every solver is
weighted and the EKF's measurement covariance is the identity.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from spacearm.controller.calibration.errormodel import ErrorModel
from spacearm.controller.calibration.measurement_models import MeasurementModel, PlaneModel
from spacearm.controller.calibration.residuals import PlaneTarget, free_indices

Array = NDArray[np.float64]


@dataclass
class Block:
    """Readings of one instrument: postures Q (N, n), readings, the model, and the noise.

    `sigma` is per row of the model (k,) or one number; `cov` (N, k, k) overrides it.
    """
    model: MeasurementModel
    Q: Array
    measured: Array
    sigma: ArrayLike = 1e-3
    cov: Array | None = None
    label: str = ""

    def __post_init__(self) -> None:
        self.Q = np.atleast_2d(np.asarray(self.Q, float))
        self.measured = np.asarray(self.measured, float)
        if len(self.measured) != len(self.Q):
            raise ValueError(f"{self.label or self.model.name}: {len(self.measured)} readings for "
                             f"{len(self.Q)} postures")
        if not self.label:
            self.label = self.model.name

    def subset(self, rows: ArrayLike) -> "Block":
        rows = np.asarray(rows, dtype=int)
        return Block(self.model, self.Q[rows], self.measured[rows], self.sigma,
                     None if self.cov is None else self.cov[rows], self.label)

    def whitening(self) -> Array:
        """(N, k, k) with W cov W^T = I."""
        k = self.model.rows
        if self.cov is not None:
            return np.linalg.inv(np.linalg.cholesky(self.cov))
        s = np.broadcast_to(np.asarray(self.sigma, float), (k,))
        return np.broadcast_to(np.diag(1.0 / s), (len(self.Q), k, k))


@dataclass
class CompositeProblem:
    """Parameters of the arm and of every block's instrument, fitted to all blocks at once."""
    model: ErrorModel
    blocks: list[Block]
    free: list[str]
    x0: Array | None = None
    names: tuple[str, ...] = field(init=False)
    free_idx: NDArray[np.int_] = field(init=False)
    extra_slices: list[slice] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        names = list(self.model.names)
        nominal = [self.model.nominal]
        self.extra_slices = []
        seen: dict[str, int] = {}
        for b in self.blocks:
            ext = list(b.model.extra_names)
            clash = [n for n in ext if n in seen]
            if clash and any(seen[n] != id(b.model) for n in clash):
                raise ValueError(f"two blocks use the parameter names {clash}: give them different prefixes")
            if clash:          # the same instrument object in two blocks shares its parameters
                start = names.index(ext[0])
                self.extra_slices.append(slice(start, start + len(ext)))
                continue
            self.extra_slices.append(slice(len(names), len(names) + len(ext)))
            names += ext
            nominal.append(b.model.extra_nominal)
            seen.update({n: id(b.model) for n in ext})
        self.names = tuple(names)
        self._nominal = np.concatenate(nominal)
        self.free_idx = free_indices(self.names, self.free)
        if self.x0 is None:
            self.x0 = self._nominal.copy()
        self.x0 = np.asarray(self.x0, float)
        self._W = [np.ascontiguousarray(b.whitening()) for b in self.blocks]

    # ------------------------------------------------------------ solver interface (duck Problem)
    sigma = np.ones(1)          # rows are whitened: unit noise per row
    cov = None
    rows = 1
    kind = "composite"

    @property
    def plane(self) -> PlaneTarget | None:
        """The first plane block's target (identifiability's gauge ordering reads it)."""
        for b in self.blocks:
            if isinstance(b.model, PlaneModel):
                return PlaneTarget(b.model.normal, b.model.offset, b.model.prefix)
        return None

    @property
    def n_configs(self) -> int:
        """Number of scalar (whitened) rows: the EKF processes them one by one."""
        return sum(len(b.Q) * b.model.rows for b in self.blocks)

    @property
    def n_postures(self) -> int:
        return sum(len(b.Q) for b in self.blocks)

    def nominal(self) -> Array:
        return self._nominal.copy()

    def full(self, x_free: ArrayLike, base: Array | None = None) -> Array:
        out = (self.x0 if base is None else base).copy()
        out[self.free_idx] = x_free
        return out

    def whitening(self) -> None:
        return None

    def with_free(self, free: list[str], x0: Array | None = None) -> "CompositeProblem":
        return CompositeProblem(self.model, self.blocks, list(free), self.x0 if x0 is None else x0)

    def with_blocks(self, blocks: list[Block]) -> "CompositeProblem":
        return CompositeProblem(self.model, blocks, list(self.free), self.x0)

    # ---------------------------------------------------------------------------- evaluation
    def block_residuals(self, x_full: ArrayLike, jacobian: bool = True,
                        blocks: list[Block] | None = None) -> list[tuple[Array, Array | None]]:
        """Per block: unweighted r (N, k) and d predicted / d x_full (N, k, P) (None if not asked)."""
        x_full = np.asarray(x_full, float)
        npar = self.model.n_params
        out = []
        for b, sl in zip(self.blocks if blocks is None else blocks, self.extra_slices):
            T, Jt = self.model.poses_and_jacobian(x_full[:npar], b.Q)
            r, A_arm, A_e = b.model.residual(T, Jt, x_full[sl], b.measured)
            if not jacobian:
                out.append((r, None))
                continue
            A = np.zeros((len(T), b.model.rows, len(self.names)))
            A[:, :, :npar] = A_arm
            A[:, :, sl] = A_e
            out.append((r, A))
        return out

    def residual_and_jacobian(self, x_full: ArrayLike) -> tuple[Array, Array]:
        """Whitened rows: r (R, 1), A (R, 1, P)."""
        rs, As = [], []
        for (r, A), W in zip(self.block_residuals(x_full), self._W):
            # Batched matmul: several times faster than the equivalent einsum for (N, 6, 6) @ (N, 6, P).
            rs.append(np.matmul(W, r[:, :, None]).reshape(-1))
            As.append(np.matmul(W, A).reshape(-1, A.shape[-1]))
        return np.concatenate(rs)[:, None], np.concatenate(As)[:, None, :]

    def position_errors(self, x_full: ArrayLike, truth: list[Array] | None = None) -> list[Array]:
        """Per block, the position part of the (unweighted) residuals (N, rows) in metres;
        against `truth` readings instead of the measured ones when given."""
        x_full = np.asarray(x_full, float)
        npar = self.model.n_params
        out = []
        for k, (b, sl) in enumerate(zip(self.blocks, self.extra_slices)):
            T = self.model.poses(x_full[:npar], b.Q)
            pred = b.model.as_rows(b.model.predict(T, x_full[sl]))
            ref = b.model.as_rows(b.measured if truth is None else truth[k])
            out.append(ref - pred)
        return out
