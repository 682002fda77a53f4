"""Small campaign files for the campaign tests (cheap trial kinds: well under a second a trial)."""
from __future__ import annotations

from pathlib import Path

import pytest

EKF_CAMPAIGN = """
[campaign]
name = "ekf_test"
kind = "calibration_ekf"
seed = {seed}
trials = {trials}

[parameters.sigma_position]
low = 0.1e-3
high = 1.0e-3
distribution = "log_uniform"

[options]
configurations = 30
validation = 50
"""


@pytest.fixture
def ekf_campaign(tmp_path: Path):
    """Writes a calibration_ekf campaign file with the given seed and trial count."""
    def make(seed: int = 3, trials: int = 8, name: str = "ekf.toml") -> Path:
        path = tmp_path / name
        path.write_text(EKF_CAMPAIGN.format(seed=seed, trials=trials))
        return path
    return make
