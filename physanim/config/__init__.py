"""YAML configs validated by pydantic, with file/override merging and precise error messages."""

from physanim.config.loader import (
    ConfigError,
    load_config,
    load_yaml,
    merge_sources,
    parse_override,
    validate,
)

__all__ = ["ConfigError", "load_config", "load_yaml", "merge_sources", "parse_override", "validate"]
