"""Configuration files (TOML in configs/) validated on load."""
from spacearm.base.config.errors import ConfigError
from spacearm.base.config.loader import load_toml_model

__all__ = ["ConfigError", "load_toml_model"]
