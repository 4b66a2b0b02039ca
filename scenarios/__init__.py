"""The scenario language: schema, safe YAML loading with source locations, bundled files."""
from .errors import ComposeError, InputError, Location

__all__ = ["ComposeError", "InputError", "Location"]
