"""The one version report (run summaries, reports, exported steps) against the versions the
imported packages state themselves."""
from __future__ import annotations

import importlib
import platform

import sysid
from sysid.store.versions import PACKAGES, software_versions


def test_versions_are_those_the_packages_state():
    report = software_versions()
    assert list(report) == ["sysid", "python", *PACKAGES]
    assert report["sysid"] == sysid.__version__ and report["python"] == platform.python_version()
    for name in PACKAGES:
        module = importlib.import_module(name)
        if hasattr(module, "__version__"):
            assert report[name] == module.__version__, name
