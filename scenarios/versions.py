"""Installed versions of compose and of its dependencies: the one place that asks
``importlib.metadata`` (for ``compose --version``, run reports, USD stage metadata and the
provenance of learned styles)."""
from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

__all__ = ["DISTRIBUTION", "SOURCE_VERSION", "compose_version", "package_versions"]

DISTRIBUTION = "compose-motion"  # the distribution name in pyproject.toml
SOURCE_VERSION = "0.0.0+src"  # compose's version when it runs from a source tree (not installed)


def compose_version() -> str:
    """compose's installed version, or :data:`SOURCE_VERSION` when it is not installed."""
    try:
        return version(DISTRIBUTION)
    except PackageNotFoundError:
        return SOURCE_VERSION


def package_versions(names, missing: str | None = None) -> dict[str, str | None]:
    """``{name: version}`` of each distribution in ``names``; compose itself through
    :func:`compose_version`, any other one that is not installed as ``missing``."""
    out: dict[str, str | None] = {}
    for name in names:
        if name == DISTRIBUTION:
            out[name] = compose_version()
            continue
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = missing
    return out
