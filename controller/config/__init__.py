"""Configuration files (TOML in configs/) validated on load."""
from controller.config.errors import ConfigError
from controller.config.loader import load_toml_model

__all__ = ["ConfigError", "load_toml_model"]
