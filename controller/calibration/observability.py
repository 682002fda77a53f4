"""Observability indices O1-O5 and optimal configuration selection (greedy + exchange).

Indices of the identification Jacobian G (m rows, L columns, singular values s_1 >= ... >= s_L),
after Sun & Hollerbach:
  O1 = (s_1 ... s_L)^(1/L) / sqrt(m)   (D-optimal)
  O2 = s_L / s_1                      (inverse condition number)
  O3 = s_L                            (E-optimal: the laser-ranger paper's choice, eq. 14)
  O4 = s_L^2 / s_1                    (noise amplification)
  O5 = 1 / sum(1 / s_i)               (A-optimal flavour)
Selection works on information matrices M = sum_i G_i^T G_i of the chosen configurations, so a
swap costs one L x L symmetric eigenvalue problem and all swaps of a sweep are one batched call.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from numpy.typing import NDArray

from spacearm.controller.calibration.residuals import Problem

Array = NDArray[np.float64]


def indices_from_singular(s: Array, m: int) -> dict[str, float]:
    s = np.sort(np.asarray(s, float))[::-1]
    if s[-1] <= 0:
        return {"O1": 0.0, "O2": 0.0, "O3": 0.0, "O4": 0.0, "O5": 0.0}
    return {"O1": float(np.exp(np.mean(np.log(s))) / np.sqrt(m)), "O2": float(s[-1] / s[0]),
            "O3": float(s[-1]), "O4": float(s[-1] ** 2 / s[0]), "O5": float(1.0 / np.sum(1.0 / s))}


def observability(G: Array) -> dict[str, float]:
    """O1-O5 of a stacked identification Jacobian (m, L)."""
    return indices_from_singular(np.linalg.svd(G, compute_uv=False), G.shape[0])


def _index_from_eigs(ev: Array, m: int, index: str) -> Array:
    """Index for a batch of information-matrix eigenvalue sets (B, L), ascending."""
    s = np.sqrt(np.clip(ev, 0.0, None))
    smin, smax = s[..., 0], s[..., -1]
    with np.errstate(divide="ignore", invalid="ignore"):
        if index == "O1":
            return np.exp(np.mean(np.log(np.maximum(s, 1e-300)), axis=-1)) / np.sqrt(m)
        if index == "O2":
            return smin / smax
        if index == "O3":
            return smin
        if index == "O4":
            return smin ** 2 / smax
        if index == "O5":
            return 1.0 / np.sum(1.0 / np.maximum(s, 1e-300), axis=-1)
    raise ValueError(f"unknown index {index!r}")


def configuration_blocks(problem: Problem, Q: Array) -> Array:
    """Per-configuration Jacobian blocks (N, k, L) of the free parameters at x0."""
    x = problem.x0
    meas = problem.predict(x, Q)
    _, A = problem.residual_and_jacobian(x, Q, meas)
    return A[:, :, problem.free_idx]


@dataclass
class Selection:
    indices: NDArray[np.int_]     # chosen rows of the candidate set
    value: float                  # chosen index value
    index: str
    sweeps: int
    elapsed: float


def select_configurations(blocks: Array, m: int, index: str = "O3", max_sweeps: int = 200,
                          top_k: int = 64) -> Selection:
    """Choose m of N candidates maximising `index`: greedy D-optimal build-up, then exchange.

    The greedy phase maximises log det(M + eps I) (E-optimality is flat until M has full rank);
    the exchange phase swaps one chosen and one unchosen configuration at a time, best swap
    first, until no swap improves the index. Deterministic.
    """
    import time
    t0 = time.perf_counter()
    N, k, L = blocks.shape
    if m > N:
        raise ValueError(f"cannot choose {m} of {N} candidates")
    infos = np.einsum("nki,nkj->nij", blocks, blocks)
    scale = np.trace(infos.sum(0)) / (N * L)
    eps = 1e-6 * scale
    chosen: list[int] = []
    M = eps * np.eye(L)
    free = np.ones(N, bool)
    for _ in range(m):
        cand = np.flatnonzero(free)
        # log det(M + G^T G) = log det M + log det(I + G M^-1 G^T): k x k per candidate.
        Minv = np.linalg.inv(M)
        S = np.eye(k) + np.einsum("nki,ij,nlj->nkl", blocks[cand], Minv, blocks[cand])
        gain = np.linalg.slogdet(S)[1]
        best = cand[int(np.argmax(gain))]
        chosen.append(best)
        free[best] = False
        M = M + infos[best]
    chosen_arr = np.array(chosen)
    M = infos[chosen_arr].sum(0)
    current = float(_index_from_eigs(np.linalg.eigvalsh(M)[None], m * k, index)[0])
    sweeps = 0
    while sweeps < max_sweeps and m < N:
        sweeps += 1
        out = np.flatnonzero(~np.isin(np.arange(N), chosen_arr))
        # Rank all swaps (i leaves, j enters) by a first-order estimate of the change in the
        # smallest eigenvalues, then evaluate the most promising ones exactly; only if none of
        # them improves, evaluate every swap exactly (so the result is a true 1-exchange optimum).
        w, V = np.linalg.eigh(M)
        Vb = V[:, : min(3, L)]
        proj = np.einsum("nki,il->nl", blocks, Vb) if k == 1 else None
        if proj is None:
            gain = np.einsum("nkl->nl", np.einsum("nki,il->nkl", blocks, Vb) ** 2)
        else:
            gain = proj ** 2
        score = (gain[out][None, :, 0] - gain[chosen_arr][:, None, 0])
        order = np.argsort(-score, axis=None)
        found = False
        for cand_set in (order[:top_k], order):
            ii, jj = np.unravel_index(cand_set, score.shape)
            Ms = M[None] - infos[chosen_arr[ii]] + infos[out[jj]]
            vals = _index_from_eigs(np.linalg.eigvalsh(Ms), m * k, index)
            b = int(np.argmax(vals))
            if vals[b] > current * (1 + 1e-12):
                i, j = ii[b], jj[b]
                M = M - infos[chosen_arr[i]] + infos[out[j]]
                chosen_arr[i] = out[j]
                current = float(vals[b])
                found = True
                break
        if not found:
            break
    return Selection(np.sort(chosen_arr), current, index, sweeps, time.perf_counter() - t0)


def random_subsets_best(blocks: Array, m: int, count: int, rng: np.random.Generator,
                        index: str = "O3", batch: int = 2000) -> tuple[float, Array]:
    """Best and all index values of `count` random m-subsets (the benchmark baseline)."""
    N, k, L = blocks.shape
    infos = np.einsum("nki,nkj->nij", blocks, blocks).reshape(N, L * L)
    values = []
    for start in range(0, count, batch):
        b = min(batch, count - start)
        pick = np.argsort(rng.random((b, N)), axis=1)[:, :m]
        ind = np.zeros((b, N))
        np.put_along_axis(ind, pick, 1.0, axis=1)
        Ms = (ind @ infos).reshape(b, L, L)
        values.append(_index_from_eigs(np.linalg.eigvalsh(Ms), m * k, index))
    v = np.concatenate(values)
    return float(v.max()), v


# ------------------------------------------------------------------------ candidate constraints
def laser_ok(problem: Problem, Q: Array, x_full: Array | None = None, h_range=(0.05, 3.0),
             min_incidence_cos: float = 0.3) -> NDArray[np.bool_]:
    """Postures whose beam hits the plane ahead of the ranger, within range, not grazing."""
    x = problem.x0 if x_full is None else x_full
    T = problem.model.poses(x[: problem.model.n_params], Q)
    n = x[problem.model.n_params: problem.model.n_params + 3]
    f = x[problem.model.n_params + 3]
    nb = T[:, :3, 2] @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        h = -(T[:, :3, 3] @ n + f) / nb
    cos_inc = np.abs(nb) / np.linalg.norm(n)
    return (h > h_range[0]) & (h < h_range[1]) & (cos_inc > min_incidence_cos)


def board_in_view(T_board_cam: Array, fov_half_angle: float = np.radians(30.0),
                  z_range=(0.2, 3.0)) -> NDArray[np.bool_]:
    """Eye-in-hand: board origin in front of the camera, inside the cone, board facing it."""
    T_cam_board = np.linalg.inv(T_board_cam)
    p = T_cam_board[:, :3, 3]
    z = p[:, 2]
    ang = np.arctan2(np.linalg.norm(p[:, :2], axis=1), z)
    facing = T_cam_board[:, 2, 2] < -0.5    # board normal points back at the camera
    return (z > z_range[0]) & (z < z_range[1]) & (ang < fov_half_angle) & facing


def sample_valid(kin_q_sampler: Callable[[int, np.random.Generator], Array],
                 ok: Callable[[Array], NDArray[np.bool_]], count: int,
                 rng: np.random.Generator, max_rounds: int = 200) -> Array:
    """Rejection-sample `count` configurations passing `ok`."""
    got: list[Array] = []
    n = 0
    for _ in range(max_rounds):
        Q = kin_q_sampler(max(4 * count, 256), rng)
        Q = Q[ok(Q)]
        got.append(Q)
        n += len(Q)
        if n >= count:
            return np.concatenate(got)[:count]
    raise RuntimeError(f"only {n} of {count} valid configurations found")
