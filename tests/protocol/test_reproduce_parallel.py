"""The protocol's results are a function of config, data and seed: side-by-side workers and
one process give the same tables."""
import re

import pandas as pd
import pytest

from sysid.protocol.reproduce import reproduce


@pytest.mark.slow
def test_parallel_workers_give_the_same_tables(dataset_dir, tmp_path):
    tiny = {"training": {"epochs": 2, "warm_start_epochs": 3, "batch_size": 512}}
    names = ["mmg_lab", "nn_D1", "hybrid_D1"]
    said: dict[int, list[str]] = {1: [], 2: []}
    one = reproduce(tmp_path / "one", only=names, overrides=tiny, progress=False, log=said[1].append, jobs=1)
    two = reproduce(tmp_path / "two", only=names, overrides=tiny, progress=False, log=said[2].append, jobs=2)
    assert one.failed == two.failed == {}
    for jobs, lines in said.items():  # every run counted once, in the order it started or was done: 1/3, 2/3, 3/3
        counted = [line.split("]")[0] for line in lines if re.match(r"\[\d+/3\] \w+[: ]", line)]
        assert counted == ["[1/3", "[2/3", "[3/3"], (jobs, lines)
    a = pd.read_csv(tmp_path / "one" / "comparison.csv")
    b = pd.read_csv(tmp_path / "two" / "comparison.csv")
    assert len(a) == 3 * 6 * 2 * 2 - 6 * 2 * 2  # MMG in D1 and D2, NN and hybrid in D1; 6 scenarios, 2 horizons
    pd.testing.assert_frame_equal(a, b)
    assert (tmp_path / "one" / "table7.md").read_text() == (tmp_path / "two" / "table7.md").read_text()
    indices = [pd.read_csv(tmp_path / d / "maneuver_indices.csv") for d in ("one", "two")]
    pd.testing.assert_frame_equal(*indices)  # recorded maneuvers beside every model's prediction
    assert list(dict.fromkeys(indices[0].model)) == ["recorded", "MMG (lab X'vr)", "NN D1", "Hybrid D1"]
    assert set(indices[0].scenario) == {"Turning 20", "Turning 35", "Zigzag 20/20", "Zigzag 30/30"}
