"""Shared fixtures: the oracle vectors and the real dataset (skipped clearly when absent)."""
from __future__ import annotations

import os
import sys
from pathlib import Path

import pandas as pd
import pytest

from sysid.errors import DataError

ROOT = Path(__file__).resolve().parents[1]
# helpers shared by tests (harnesses, synthetic runs, tiny experiments), imported by name
sys.path.insert(0, str(Path(__file__).resolve().parent / "support"))


def _shared() -> Path:
    env = os.environ.get("SYSID_SHARED")
    return Path(env) if env else ROOT.parent / "shared"


@pytest.fixture(scope="session")
def oracle_dir() -> Path:
    path = _shared() / "oracle"
    if not (path / "mmg_vectors_public.csv").is_file():
        pytest.skip(f"oracle vectors not found in {path} (set SYSID_SHARED to the shared/ directory)")
    return path


@pytest.fixture(scope="session")
def oracle_vectors(oracle_dir) -> pd.DataFrame:
    return pd.read_csv(oracle_dir / "mmg_vectors_public.csv")


@pytest.fixture(scope="session")
def dataset_dir() -> Path:
    from sysid.data.datasets import data_dir
    try:
        return data_dir()
    except DataError as exc:
        pytest.skip(f"real dataset unavailable: {exc}")


@pytest.fixture(scope="session")
def files(dataset_dir) -> dict[str, Path]:
    """The tiny experiment's training and test berthing runs (`tiny_experiment.tiny_files`)."""
    from tiny_experiment import tiny_files
    return tiny_files(dataset_dir)


@pytest.fixture(scope="session")
def trained(tmp_path_factory, files) -> Path:
    """A run directory written by `sysid train` (tiny hybrid, with model.pt and knn.pt);
    tests copy it before changing it."""
    from tiny_experiment import train_tiny_run
    return train_tiny_run(tmp_path_factory.mktemp("trained"), files)
