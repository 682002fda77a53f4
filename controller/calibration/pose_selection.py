"""Posture selection for real campaigns, for every measurement model.

  select_for_model   the O1 (D-optimal) / O3 (E-optimal) choice of m postures among candidates,
                     from the whitened Jacobian blocks of any measurement model (observability.py)
  next_postures      given the postures already measured, the candidates that most improve the
                     worst-determined parameters (greedy D-optimal on top of the existing
                     information), with each parameter's predicted 1-sigma before and after:
                     what to measure in the next session to make a weak parameter identifiable.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spacearm.controller.calibration.composite import Block, CompositeProblem
from spacearm.controller.calibration.observability import Selection, select_configurations

Array = NDArray[np.float64]


def probe_block(template: Block, Q: Array) -> Block:
    """`template`'s instrument at postures Q, with placeholder readings (for Jacobians only)."""
    return Block(template.model, Q, np.zeros((len(Q),) + template.measured.shape[1:]), template.sigma,
                 None, template.label)


def candidate_blocks(problem: CompositeProblem, template: Block, Q: Array) -> Array:
    """Whitened Jacobian blocks (N, k, L) of problem.free for `template`'s instrument at postures Q."""
    k = template.model.rows
    probe = probe_block(template, Q)
    cp = CompositeProblem(problem.model, [probe], list(problem.free), _x_for(problem, probe))
    _, A = cp.residual_and_jacobian(cp.x0)
    return A[:, 0, cp.free_idx].reshape(len(Q), k, -1)


def _x_for(problem: CompositeProblem, probe: Block) -> Array:
    """The problem's current values for a composite of the probe block alone (same names)."""
    cp = CompositeProblem(problem.model, [probe], [])
    x = cp.nominal()
    for i, n in enumerate(cp.names):
        if n in problem.names:
            x[i] = problem.x0[problem.names.index(n)]
    return x


def select_for_model(problem: CompositeProblem, template: Block, Q: Array, m: int,
                     index: str = "O3") -> Selection:
    """Choose m of the candidate postures Q for this instrument (greedy + exchange)."""
    return select_configurations(candidate_blocks(problem, template, Q), m, index)


@dataclass
class NextPostures:
    indices: NDArray[np.int_]            # rows of the candidate set, in the order chosen
    std_before: dict[str, float]         # predicted 1-sigma with the data so far (inf: unidentifiable)
    std_after: dict[str, float]          # with the proposed postures added
    rank_before: int
    rank_after: int

    def most_improved(self, count: int = 5) -> list[str]:
        def gain(n: str) -> float:
            b, a = self.std_before[n], self.std_after[n]
            return np.inf if not np.isfinite(b) and np.isfinite(a) else b / max(a, 1e-300)
        return sorted(self.std_before, key=lambda n: -gain(n))[:count]


def _std(M: Array, tol: float = 1e-10) -> tuple[Array, int]:
    """Per-parameter 1-sigma from an information matrix; inf where not identifiable."""
    w, V = np.linalg.eigh(M)
    good = w > tol * max(w.max(), 1e-300)
    C = (V[:, good] / w[good]) @ V[:, good].T
    var = np.diag(C).copy()
    # A parameter with a component in the null space is not determined at all.
    null = V[:, ~good]
    undetermined = np.sum(null ** 2, axis=1) > 1e-6 if null.size else np.zeros(len(M), bool)
    var[undetermined] = np.inf
    return np.sqrt(var), int(good.sum())


def next_postures(problem: CompositeProblem, template: Block, Q: Array, count: int,
                  target: list[str] | None = None) -> NextPostures:
    """The `count` candidate postures (rows of Q) measured with `template`'s instrument that add
    the most information to what `problem`'s data already carry (greedy log-det), so that the
    weakest and unidentifiable parameters among problem.free become determined. With `target`
    (parameter names) each step instead takes the posture that most lowers the summed variance
    of those parameters (A-optimal on them)."""
    _, A = problem.residual_and_jacobian(problem.x0)
    G0 = A[:, 0, problem.free_idx]
    M0 = G0.T @ G0
    blocks = candidate_blocks(problem, template, Q)
    L = M0.shape[0]
    scale = max(np.trace(M0), np.einsum("nki,nki->", blocks, blocks) / max(len(Q), 1)) / L
    M = M0 + 1e-9 * scale * np.eye(L)
    chosen: list[int] = []
    free = np.ones(len(Q), bool)
    for _ in range(min(count, len(Q))):
        cand = np.flatnonzero(free)
        Minv = np.linalg.inv(M)
        S = np.eye(blocks.shape[1]) + np.einsum("nki,ij,nlj->nkl", blocks[cand], Minv, blocks[cand])
        if target:
            # Woodbury: C' = C - C G^T S^-1 G C; variance drop of the targets = diag of the update.
            t = [problem.free.index(n) for n in target]
            CG = np.einsum("ij,nkj->nik", Minv[t], blocks[cand])                # (n, T, k)
            drop = np.einsum("ntk,nkl,ntl->n", CG, np.linalg.inv(S), CG)
            best = cand[int(np.argmax(drop))]
        else:
            best = cand[int(np.argmax(np.linalg.slogdet(S)[1]))]
        chosen.append(int(best))
        free[best] = False
        M = M + blocks[best].T @ blocks[best]
    s0, r0 = _std(M0)
    s1, r1 = _std(M0 + sum(blocks[i].T @ blocks[i] for i in chosen))
    return NextPostures(np.array(chosen), dict(zip(problem.free, s0.tolist())),
                        dict(zip(problem.free, s1.tolist())), r0, r1)
