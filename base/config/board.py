"""The calibration checkerboard's description (configs/calibration/board.toml): read by the
camera calibration routine and by the simulator that places the board in the cell."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from pydantic import Field

from spacearm.base.config.loader import StrictModel, load_toml_model
from spacearm.base.config.scene import ScenePose
from spacearm.base.paths import CONFIGS

DEFAULT_BOARD = CONFIGS / "calibration" / "board.toml"


class BoardConfig(StrictModel):
    squares: tuple[int, int] = Field(description="squares along x, y (inner corners: one fewer)")
    square: float = Field(gt=0.001, lt=0.5, description="m")
    pose: ScenePose                       # base_T_board, nominal
    true_offset: ScenePose = ScenePose(xyz=(0.0, 0.0, 0.0))
    dark: float = Field(default=0.05, ge=0.0, le=1.0)
    light: float = Field(default=0.85, ge=0.0, le=1.0)
    margin: float = Field(default=0.015, ge=0.0, le=0.5, description="m")

    @property
    def inner(self) -> tuple[int, int]:
        return self.squares[0] - 1, self.squares[1] - 1

    def object_points(self) -> np.ndarray:
        """Inner corners in the board frame, row-major (x fastest), (N, 3)."""
        nx, ny = self.inner
        xs, ys = np.meshgrid(np.arange(nx), np.arange(ny))
        return np.stack([xs.ravel(), ys.ravel(), np.zeros(nx * ny)], axis=1) * self.square


def load_board(path: str | Path = DEFAULT_BOARD) -> BoardConfig:
    return load_toml_model(path, BoardConfig)
