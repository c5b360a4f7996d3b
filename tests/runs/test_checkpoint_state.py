"""The training checkpoint as `CheckpointState`: a checkpoint the trainer wrote reads into the
dataclass and writes back to the same content (``torch.load(weights_only=True)`` both ways);
a checkpoint missing a key is refused with one line naming it."""
from __future__ import annotations

import pytest
import torch

from sysid.config.experiment import load_experiment
from sysid.errors import CheckpointError
from sysid.identify.checkpoint import CheckpointState, TrainingCheckpoint, pack, unpack
from sysid.identify.trainer import Trainer
from sysid.runs.lifecycle import training_runs
from tiny_experiment import tiny_experiment


def _same(a, b) -> bool:
    """Equal content: same keys in the same order, equal tensors (dtype and values)."""
    if isinstance(a, torch.Tensor):
        return isinstance(b, torch.Tensor) and a.dtype == b.dtype and torch.equal(a, b)
    if isinstance(a, dict):
        return isinstance(b, dict) and list(a) == list(b) and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return type(a) is type(b) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return type(a) is type(b) and a == b


@pytest.fixture(scope="module")
def written(dataset_dir, tmp_path_factory):
    """(checkpoint file, config) the trainer left after a 3-epoch training stage."""
    tmp = tmp_path_factory.mktemp("checkpoint")
    exp = load_experiment(tiny_experiment(tmp / "tiny.toml", dataset_dir, seed=1, epochs=3, warm_start_epochs=2))
    trainer = Trainer(exp, progress=False, log=lambda m: None, checkpoint=tmp / "ckpt.pt").fit(training_runs(exp))
    return tmp / "ckpt.pt", exp.to_toml(), trainer


def test_checkpoint_reads_into_the_state_and_writes_back_the_same(written, tmp_path):
    path, config, trainer = written
    state = TrainingCheckpoint(path, config).load()
    assert (state.stage, state.epoch) == ("train", 3)
    assert [row["epoch"] for row in state.stage_history] == [1, 2, 3]
    losses = [row["early_stopping_loss"] for row in state.stage_history]
    assert state.best_loss == min(losses) and state.best_epoch == 1 + losses.index(min(losses))
    assert state.summary["n_train_windows"] == trainer.summary_.n_train_windows
    first = torch.load(path, weights_only=True)
    TrainingCheckpoint(tmp_path / "again.pt", config, first["files"]).save(state)
    again = torch.load(tmp_path / "again.pt", weights_only=True)
    assert list(first)[:3] == ["version", "config", "files"] and _same(first, again)
    assert _same(CheckpointState.from_state_dict(again, "again.pt").to_state_dict(), state.to_state_dict())


def test_the_checkpoint_keeps_the_bytes_of_the_files_its_config_names(written, dataset_dir):
    """``files``: the SHA-256 of the ship file and of each training log, in the config's
    order (hashlib on the dataset's files), so a moved project's checkpoint is still its."""
    import hashlib

    from sysid.mmg.ship import resolve_ship_path
    from tiny_experiment import TRAIN_FILES
    path, _, _ = written
    files = torch.load(path, weights_only=True)["files"]
    digest = lambda p: hashlib.sha256(p.read_bytes()).hexdigest()  # noqa: E731
    assert files == {"ship": [digest(resolve_ship_path("esso_osaka"))],
                     "train": [digest(dataset_dir / "berthing" / name) for name in TRAIN_FILES],
                     "validation": [], "test": []}


@pytest.mark.parametrize("key", ["generator", "best_state"])
def test_a_checkpoint_missing_a_key_is_refused_naming_it(written, tmp_path, key):
    path, config, _ = written
    raw = torch.load(path, weights_only=True)
    del raw[key]
    torch.save(raw, tmp_path / "ckpt.pt")
    with pytest.raises(CheckpointError, match=rf"training checkpoint has no '{key}'; delete it to start afresh$"):
        TrainingCheckpoint(tmp_path / "ckpt.pt", config).load()


def test_a_packed_table_unpacks_to_equal_tensors():
    """`pack` then `unpack` (through a weights_only file) gives the same names in the same
    order and equal tensors: dtypes, shapes (scalars, empty, a transposed view) and values."""
    g = torch.Generator().manual_seed(3)
    tensors = {"w": torch.randn(4, 3, generator=g, dtype=torch.float64).t(), "b": torch.randn(3, generator=g),
               "step": torch.tensor(7.0), "n": torch.tensor([2, 5], dtype=torch.int64), "none": torch.zeros(0, 2),
               "c": torch.tensor(-0.0081, dtype=torch.float64)}
    packed = pack(tensors)
    assert sorted(packed["values"]) == ["float32", "float64", "int64"] and packed["values"]["float64"].numel() == 13
    back = unpack(packed, "x.pt", "model")
    assert list(back) == list(tensors)
    assert all(b.dtype == t.dtype and b.shape == t.shape and torch.equal(b, t) for b, t in zip(back.values(), tensors.values()))
    assert unpack(pack({}), "x.pt", "model") == {}
    for layout in ("w\tfloat64\t3,5", "w\tfloat64\t-3,4", "w\tfloat16\t3,4", "w\tfloat64"):
        with pytest.raises(CheckpointError, match=r"^x.pt: training checkpoint's 'model' is not a packed tensor table"):
            unpack({"layout": layout, "values": {"float64": torch.zeros(12, dtype=torch.float64)}}, "x.pt", "model")


def test_a_damaged_packed_table_is_refused_in_one_line(written, tmp_path):
    path, config, _ = written
    raw = torch.load(path, weights_only=True)
    assert raw["version"] == 2
    raw["model"]["values"]["float32"] = raw["model"]["values"]["float32"][:-1]  # one number short
    torch.save(raw, tmp_path / "ckpt.pt")
    with pytest.raises(CheckpointError, match=r"ckpt.pt: training checkpoint's 'model' is not a packed tensor "
                                              r"table; delete it to start afresh$"):
        TrainingCheckpoint(tmp_path / "ckpt.pt", config).load()


def test_the_packed_values_are_the_tensors_flattened_in_order():
    """`pack`'s flat values per dtype equal torch.cat of the tensors' flattened values (the
    stand-in a torch without its private flatten gets)."""
    from sysid.identify.checkpoint import pack
    a, b, c = torch.arange(6.0).reshape(2, 3).t(), torch.tensor(7.0), torch.arange(3, dtype=torch.int64)
    packed = pack({"a": a, "b": b, "c": c})
    assert torch.equal(packed["values"]["float32"], torch.cat([a.reshape(-1), b.reshape(-1)]))
    assert torch.equal(packed["values"]["int64"], c)
