"""The installed enclose's version: `enclose --version`, every run's metrics.json and
launch.json, `enclose.__version__`."""

from __future__ import annotations

from functools import cache
from importlib.metadata import PackageNotFoundError, version

UNKNOWN = "0+unknown"  # a source tree that was never installed


@cache
def enclose_version() -> str:
    try:
        return version("enclose")
    except PackageNotFoundError:
        return UNKNOWN
