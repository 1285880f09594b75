"""YAML configs validated by pydantic, with file/override merging and precise error messages."""

from physanim.config.loader import (
    ConfigError,
    deep_merged,
    load_config,
    load_yaml,
    merge_sources,
    parse_override,
    validate,
)

__all__ = [
    "ConfigError",
    "deep_merged",
    "load_config",
    "load_yaml",
    "merge_sources",
    "parse_override",
    "validate",
]
