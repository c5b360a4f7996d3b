"""Seeds side by side (`sysid.identify.side_by_side`): two seeds of a tiny real-data hybrid
trained in one process on the member axis end with the models, histories and validation
losses each seed reaches alone, also across an early stop of one seed and a resume."""
from __future__ import annotations

import pytest
import torch

from sysid.config.experiment import parse_experiment
from sysid.data.recordings import read_runs
from sysid.device import compute_threads
from sysid.errors import ConfigError
from sysid.hybrid.force_models import PerMember
from sysid.identify.checkpoint import TrainingCheckpoint
from sysid.identify.side_by_side import fit_side_by_side, refusal
from sysid.identify.trainer import Trainer
from tiny_experiment import TRAIN_FILES

VALIDATION_FILE = "berthing_12-Nov-2020_11_21_46.csv"
SEEDS = (3, 4)


def _experiment(seed: int, model: str = "hybrid", **training):
    doc = {"experiment": {"name": "pair", "model": model, "seed": seed},
           "network": {"hidden": [16, 16]},
           "training": {"epochs": 12, "patience": 3, "warm_start_epochs": 3, "batch_size": 64, "steps": 5,
                        "learning_rate": 1e-2, "lr_factor": 0.5, "lr_patience": 1, **training},
           "gate": {"k": 5, "space": "inputs"}}
    return parse_experiment(doc)


@pytest.fixture(autouse=True)
def one_thread():
    with compute_threads(1):  # as `sysid train` trains
        yield


@pytest.fixture(scope="module")
def logs(dataset_dir):
    berthing = dataset_dir / "berthing"
    return read_runs([berthing / f for f in TRAIN_FILES]), read_runs([berthing / VALIDATION_FILE])


def _alone(seed: int, logs, **kwargs) -> Trainer:
    return Trainer(_experiment(seed), progress=False, log=lambda _: None, **kwargs).fit(*logs)


def _assert_same(pair: Trainer, alone: Trainer) -> None:
    for (name, a), b in zip(PerMember(pair.model_).state_dict().items(), PerMember(alone.model_).state_dict().values()):
        assert torch.allclose(a, b, rtol=1e-5, atol=1e-7), name
    h, g = pair.history_, alone.history_
    assert list(h.epoch) == list(g.epoch) and list(h.stage) == list(g.stage)
    for column in ("train_loss", "train_velocity", "train_penalty", "early_stopping_loss"):
        assert h[column].to_numpy() == pytest.approx(g[column].to_numpy(), rel=1e-5), column
    assert pair.summary_.val_loss_multistep == pytest.approx(alone.summary_.val_loss_multistep, rel=1e-5)
    assert pair.summary_.best_epoch == alone.summary_.best_epoch
    assert pair.summary_.stopped == alone.summary_.stopped


def test_two_seeds_side_by_side_equal_each_alone(logs, tmp_path):
    alone = [_alone(seed, logs) for seed in SEEDS]
    # the seeds stop early at different epochs: the first stopped is frozen while the other trains on
    assert [t.summary_.stopped["train"] for t in alone] == ["early stop", "early stop"]
    assert alone[0].summary_.epochs != alone[1].summary_.epochs
    pair = fit_side_by_side([Trainer(_experiment(seed), progress=False, log=lambda _: None,
                                     checkpoint=tmp_path / f"seed{seed}.pt") for seed in SEEDS], *logs)
    for p, a in zip(pair, alone):
        _assert_same(p, a)
    assert not torch.allclose(pair[0].model_.correction_net.weights[0], pair[1].model_.correction_net.weights[0])


def test_two_nn_only_seeds_side_by_side_equal_each_alone(logs, tmp_path, monkeypatch):
    """NN-only trains through its training right-hand side (`sysid.hybrid.fused_rate.nn_rate`),
    alone (K = 1) and side by side (K = 2): each seed ends with the model, history and
    validation loss it reaches alone."""
    from sysid.hybrid import force_models
    shapes = []
    original = force_models.nn_rate

    def counted(state, inputs, plan):
        shapes.append(state.shape[0])
        return original(state, inputs, plan)
    monkeypatch.setattr(force_models, "nn_rate", counted)
    alone = [Trainer(_experiment(seed, "nn"), progress=False, log=lambda _: None).fit(*logs) for seed in SEEDS]
    assert shapes and set(shapes) == {1}
    shapes.clear()
    pair = fit_side_by_side([Trainer(_experiment(seed, "nn"), progress=False, log=lambda _: None,
                                     checkpoint=tmp_path / f"seed{seed}.pt") for seed in SEEDS], *logs)
    assert shapes and set(shapes) <= {1, 2} and 2 in shapes  # K = 1 once a seed has stopped
    for p, a in zip(pair, alone):
        _assert_same(p, a)


def test_interrupted_side_by_side_resumes_alone_to_the_same_model(logs, tmp_path, monkeypatch):
    """Each seed's checkpoint has the solo layout: a seed interrupted side by side resumes
    alone (or side by side) to the model of an uninterrupted run."""
    whole = [_alone(seed, logs) for seed in SEEDS]
    saves = {"n": 0}
    original = TrainingCheckpoint.save

    def save_then_interrupt(self, state):
        original(self, state)
        saves["n"] += 1
        if saves["n"] == 4 and state.stage == "train":  # after epoch 2 of both seeds
            raise KeyboardInterrupt

    paths = [tmp_path / f"seed{seed}.pt" for seed in SEEDS]
    monkeypatch.setattr(TrainingCheckpoint, "save", save_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        fit_side_by_side([Trainer(_experiment(seed), progress=False, log=lambda _: None, checkpoint=path)
                          for seed, path in zip(SEEDS, paths)], *logs)
    monkeypatch.setattr(TrainingCheckpoint, "save", original)
    assert all(path.is_file() for path in paths)
    said: list[str] = []
    alone = Trainer(_experiment(SEEDS[0]), progress=False, log=said.append, checkpoint=paths[0], resume=True)
    _assert_same(alone.fit(*logs), whole[0])
    assert "train: resumed after epoch 2" in " ".join(said)
    pair = fit_side_by_side([Trainer(_experiment(SEEDS[1]), progress=False, log=lambda _: None,
                                     checkpoint=paths[1], resume=True)], *logs)
    _assert_same(pair[0], whole[1])


def test_seeds_that_cannot_share_are_refused(logs):
    blocks = parse_experiment({"experiment": {"name": "b", "model": "hybrid", "seed": 1}})
    assert "drawn with the seed" in refusal(blocks)
    assert refusal(blocks, validation_logs=True) is None
    with pytest.raises(ConfigError, match="differs in more than its seed"):
        fit_side_by_side([Trainer(_experiment(1)), Trainer(_experiment(2, batch_size=32))], *logs)
