"""The one version lookup (scenarios/versions.py): installed versions, the source-tree
fallback, missing packages, and no other module asking importlib.metadata."""
from __future__ import annotations

import importlib.metadata as md
from pathlib import Path

import pytest

from scenarios import versions
from scenarios.versions import SOURCE_VERSION, compose_version, package_versions

ROOT = Path(__file__).resolve().parents[2]


def test_installed_versions_are_the_metadata_ones():
    assert package_versions(["numpy", "pydantic"]) == {"numpy": md.version("numpy"), "pydantic": md.version("pydantic")}


def test_missing_packages_and_the_source_tree(monkeypatch):
    assert package_versions(["no-such-distribution-xyz"], missing="unknown") == {"no-such-distribution-xyz": "unknown"}
    assert package_versions(["no-such-distribution-xyz"]) == {"no-such-distribution-xyz": None}

    def not_installed(name):
        raise md.PackageNotFoundError(name)
    monkeypatch.setattr(versions, "version", not_installed)
    assert compose_version() == SOURCE_VERSION
    assert package_versions(["compose-motion"], missing="unknown") == {"compose-motion": SOURCE_VERSION}


@pytest.mark.parametrize("pkg", ["scenarios", "scenegraph", "schedules"])
def test_no_other_module_reads_package_metadata(pkg):
    readers = [str(p.relative_to(ROOT)) for p in (ROOT / pkg).rglob("*.py")
               if "importlib.metadata" in p.read_text(encoding="utf-8") and p.name != "versions.py"]
    assert readers == []
