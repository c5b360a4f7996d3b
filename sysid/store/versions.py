"""The software an output was made with: one version report for run summaries, reports and
exported steps."""
from __future__ import annotations

import platform
from importlib.metadata import PackageNotFoundError, version

PACKAGES = ("torch", "torchdiffeq", "numpy", "pandas", "scipy", "matplotlib")  # what decides numbers and figures


def software_versions() -> dict[str, str]:
    """{"sysid": ..., "python": ..., package: version} for `PACKAGES`, read from the installed
    packages' metadata (nothing is imported); "not installed" where one is missing."""
    from sysid import __version__

    out = {"sysid": __version__, "python": platform.python_version()}
    for name in PACKAGES:
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = "not installed"
    return out
