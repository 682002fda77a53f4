class ConfigError(Exception):
    """A configuration file is missing, unreadable or invalid.

    The message names the file, the key and what is allowed, and is meant to be shown
    to the operator as is (no traceback).
    """
