"""Load a TOML file into a pydantic model, turning every failure into a ConfigError."""
from __future__ import annotations

import tomllib
from pathlib import Path
from typing import TypeVar, get_args

import annotated_types
from pydantic import BaseModel, ConfigDict, ValidationError
from pydantic.fields import FieldInfo

from spacearm.base.config.errors import ConfigError

M = TypeVar("M", bound=BaseModel)


class StrictModel(BaseModel):
    """Base of every configuration table: unknown keys are errors, values are frozen."""
    model_config = ConfigDict(extra="forbid", frozen=True)


def format_location(loc: tuple) -> str:
    """('joints', 2, 'limits', 'upper') -> 'joints #3.limits.upper': the third [[joints]] table.

    Positions in a list count from 1, as operators count joints (joint 1 is the first, as in
    the CLI's `jog 1` and the bus's joint_1); '#' marks them as counts, not Python indices."""
    text = ""
    for part in loc:
        if isinstance(part, int):
            text += f" #{part + 1}"
        else:
            text += ("." if text else "") + str(part)
    return text or "(top level)"


RANGE_ERRORS = {"greater_than", "greater_than_equal", "less_than", "less_than_equal"}


def field_for_location(model: type[BaseModel], loc: tuple) -> FieldInfo | None:
    """Walk nested pydantic models along an error location to the field it names."""
    field = None
    current: object = model
    for part in loc:
        if isinstance(part, int):
            continue
        if not (isinstance(current, type) and issubclass(current, BaseModel)):
            return None
        field = current.model_fields.get(str(part))
        if field is None:
            return None
        current = _inner_model(field.annotation)
    return field


def _inner_model(annotation: object) -> object:
    """The BaseModel inside list[M], M | None, tuple[M, ...]; else the annotation itself."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in get_args(annotation):
        inner = _inner_model(arg)
        if isinstance(inner, type) and issubclass(inner, BaseModel):
            return inner
    return annotation


def describe_range(field: FieldInfo) -> str | None:
    low = high = None
    low_open = high_open = False
    for meta in field.metadata:
        if isinstance(meta, annotated_types.Ge):
            low = meta.ge
        elif isinstance(meta, annotated_types.Gt):
            low, low_open = meta.gt, True
        elif isinstance(meta, annotated_types.Le):
            high = meta.le
        elif isinstance(meta, annotated_types.Lt):
            high, high_open = meta.lt, True
    if low is None and high is None:
        return None
    left = "(" if low_open or low is None else "["
    right = ")" if high_open or high is None else "]"
    low_text = "-inf" if low is None else f"{low:g}"
    high_text = "inf" if high is None else f"{high:g}"
    unit = f" {field.description}" if field.description else ""
    return f"allowed range {left}{low_text}, {high_text}{right}{unit}"


def describe_validation_error(path: Path, error: ValidationError, model: type[BaseModel]) -> str:
    lines = []
    for item in error.errors():
        key = format_location(item["loc"])
        message = item["msg"].removeprefix("Value error, ")
        if item["type"] in RANGE_ERRORS:
            field = field_for_location(model, item["loc"])
            allowed = describe_range(field) if field is not None else None
            message = f"out of range: {allowed}" if allowed else message
        if item["type"] == "extra_forbidden":
            message = "unknown key (check spelling)"
        got = item.get("input")
        got_text = "" if item["type"] in ("missing", "extra_forbidden") or isinstance(got, dict) else f" (got {got!r})"
        lines.append(f"{path}: {key}: {message}{got_text}")
    return "\n".join(lines)


def load_toml_model(path: str | Path, model: type[M]) -> M:
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise ConfigError(f"{path}: file not found") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror}") from None
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not UTF-8 text") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: TOML syntax error: {exc}") from None
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(describe_validation_error(path, exc, model)) from None
