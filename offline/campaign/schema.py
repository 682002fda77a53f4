"""The campaign file (TOML): which trial generator, its seed, how many trials, the parameters
drawn per trial and their ranges, and the fixed options of the trial kind.

    [campaign]
    name = "insertion"
    kind = "insertion"        # a trial kind of spacearm.offline.campaign.kinds
    seed = 1
    trials = 200

    [parameters.lateral_radius]   # m; drawn per trial from the trial's own seed
    low = 0.0
    high = 0.008
    distribution = "disc_radius"  # uniform | disc_radius (sqrt of uniform: uniform over a disc) | log_uniform

    [levels.effects]              # a designed factor instead of a draw: trial i takes
    values = [1, 1, 1, 2, 0]      # values[i % 5] (several [levels.*]: their full cross, in turn)

    [options]                     # passed to every trial unchanged
    store = "airlock_empty"

Every trial's seed comes from (campaign seed, trial index) alone, its drawn parameters from its
seed alone and its levels from its index alone, so one trial can be replayed without the others.
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from spacearm.base.config.loader import load_toml_model


class ParameterRange(BaseModel):
    model_config = ConfigDict(extra="forbid")
    low: float
    high: float
    distribution: Literal["uniform", "disc_radius", "log_uniform"] = "uniform"

    @model_validator(mode="after")
    def _ordered(self) -> "ParameterRange":
        if not self.high >= self.low:
            raise ValueError(f"high ({self.high}) must be >= low ({self.low})")
        if self.distribution == "log_uniform" and self.low <= 0:
            raise ValueError("log_uniform needs low > 0")
        return self

    def draw(self, rng: np.random.Generator) -> float:
        u = float(rng.uniform())
        if self.distribution == "disc_radius":      # uniform over the annulus low..high
            return math.sqrt(self.low ** 2 + u * (self.high ** 2 - self.low ** 2))
        if self.distribution == "log_uniform":
            return math.exp(math.log(self.low) + u * (math.log(self.high) - math.log(self.low)))
        return self.low + u * (self.high - self.low)


class Levels(BaseModel):
    model_config = ConfigDict(extra="forbid")
    values: list[float] = Field(min_length=1, max_length=10_000)


class CampaignHeader(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str = Field(min_length=1, max_length=80, pattern=r"^[A-Za-z0-9_.-]+$")
    kind: str = Field(min_length=1)
    seed: int = Field(ge=0, le=2 ** 32 - 1)
    trials: int = Field(ge=1, le=1_000_000)
    retries: int = Field(default=1, ge=0, le=10)   # re-runs of a trial that raised (not a failed trial)


class CampaignFile(BaseModel):
    model_config = ConfigDict(extra="forbid")
    campaign: CampaignHeader
    parameters: dict[str, ParameterRange] = Field(default_factory=dict)
    levels: dict[str, Levels] = Field(default_factory=dict)
    options: dict[str, Any] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _drawn_or_designed(self) -> "CampaignFile":
        both = sorted(set(self.parameters) & set(self.levels))
        if both:
            raise ValueError(f"{', '.join(both)}: both drawn ([parameters]) and designed ([levels])")
        return self


@dataclass(frozen=True)
class Campaign:
    """A loaded campaign: the validated file plus its text and hash (the result store keeps both)."""
    spec: CampaignFile
    text: str
    path: str

    @property
    def name(self) -> str:
        return self.spec.campaign.name

    @property
    def kind(self) -> str:
        return self.spec.campaign.kind

    @property
    def file_hash(self) -> str:
        return hashlib.sha256(self.text.encode()).hexdigest()[:16]

    def trial_seed(self, index: int) -> int:
        return trial_seed(self.spec.campaign.seed, index)

    def draw(self, seed: int) -> dict[str, float]:
        return draw_parameters(self.spec.parameters, seed)

    def parameters(self, index: int) -> dict[str, float]:
        """Trial `index`'s parameters: the drawn ones (from its seed) and its levels (from its index)."""
        return {**self.draw(self.trial_seed(index)), **level_values(self.spec.levels, index)}


def trial_seed(campaign_seed: int, index: int) -> int:
    """Independent stream per trial (numpy's SeedSequence), a function of (seed, index) only."""
    return int(np.random.SeedSequence([campaign_seed, index]).generate_state(1)[0])


def draw_parameters(ranges: dict[str, ParameterRange], seed: int) -> dict[str, float]:
    rng = np.random.default_rng(seed)
    return {name: ranges[name].draw(rng) for name in sorted(ranges)}


def level_values(levels: dict[str, Levels], index: int) -> dict[str, float]:
    """The full cross of the levels, in turn: the last name (sorted) changes fastest."""
    out = {}
    for name in sorted(levels, reverse=True):
        values = levels[name].values
        index, k = divmod(index, len(values))
        out[name] = float(values[k])
    return dict(sorted(out.items()))


def trial_id(index: int) -> str:
    return f"t{index:06d}"


def load_campaign(path: str | Path) -> Campaign:
    """Validate a campaign file; ConfigError (file, key, allowed range) when it is wrong, including
    a kind that does not exist or parameters the kind does not take."""
    spec = load_toml_model(path, CampaignFile)
    _check_kind(spec, str(path))
    return Campaign(spec, Path(path).read_text(), str(path))


def campaign_text(name: str, kind: str, seed: int, trials: int, levels: dict[str, list] | None = None,
                  options: dict[str, Any] | None = None) -> str:
    """A campaign file written by a program (a study, a benchmark): header, levels, options.
    Values are written as JSON, which TOML reads alike for strings, numbers, booleans and lists."""
    import json

    lines = ["[campaign]", f"name = {json.dumps(name)}", f"kind = {json.dumps(kind)}", f"seed = {int(seed)}",
             f"trials = {int(trials)}"]
    for factor, values in (levels or {}).items():
        lines += ["", f"[levels.{factor}]", f"values = {json.dumps(list(values))}"]
    if options:
        lines += ["", "[options]"] + [f"{key} = {json.dumps(value)}" for key, value in options.items()]
    return "\n".join(lines) + "\n"


def campaign_from_text(text: str, path: str = "<stored campaign>") -> Campaign:
    """The campaign kept in a result directory (replay needs no file of its own)."""
    import tomllib

    from pydantic import ValidationError

    from spacearm.base.config.errors import ConfigError
    from spacearm.base.config.loader import describe_validation_error

    try:
        spec = CampaignFile.model_validate(tomllib.loads(text))
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML ({exc})") from None
    except ValidationError as exc:
        raise ConfigError(describe_validation_error(Path(path), exc, CampaignFile)) from None
    _check_kind(spec, path)
    return Campaign(spec, text, path)


def _check_kind(spec: CampaignFile, path: str) -> None:
    from spacearm.base.config.errors import ConfigError
    from spacearm.offline.campaign.kinds import KINDS

    kind = KINDS.get(spec.campaign.kind)
    if kind is None:
        raise ConfigError(f"{path}: campaign.kind: unknown trial kind {spec.campaign.kind!r} "
                          f"(allowed: {', '.join(sorted(KINDS))})")
    for table, names in (("parameters", spec.parameters), ("levels", spec.levels)):
        for name in names:
            if name not in kind.parameters:
                raise ConfigError(f"{path}: {table}.{name}: not a parameter of kind {kind.name!r} "
                                  f"(allowed: {', '.join(kind.parameters) or 'none'})")
    for name, value in spec.options.items():
        if name not in kind.options:
            raise ConfigError(f"{path}: options.{name}: not an option of kind {kind.name!r} "
                              f"(allowed: {', '.join(kind.options) or 'none'})")
        default = kind.options[name]
        expected = (int, float) if isinstance(default, float) else type(default)
        if isinstance(value, bool) != isinstance(default, bool) or not isinstance(value, expected):
            raise ConfigError(f"{path}: options.{name}: expected {type(default).__name__} "
                              f"like the default {default!r}, got {value!r}")
