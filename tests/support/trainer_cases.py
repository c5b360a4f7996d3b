"""The trainer's results on tiny real-data cases, through its public entry points only
(`Trainer(...).fit`), saved to one file: run as ``python trainer_cases.py DATASET ROOT OUT``
with whichever `sysid` is importable and the experiment configs of ROOT/configs/experiments,
so that two versions of the package can be compared
(`tests/identify/test_trainer_parts.py`).

Cases: hybrid D1 and NN D1 (2 epochs after a 2-epoch warm start, features gate, the output
constraint), the identified MMG by gradient (2 epochs) and by Levenberg-Marquardt, a hybrid on
coefficients identified before it and one identified jointly with the FNN. Each on two berthing
logs with a third as validation, one torch thread, a checkpoint written every epoch.
"""
from __future__ import annotations

import enum
import math
import sys
from pathlib import Path

TRAIN = ("berthing_12-Nov-2020_11_07_23.csv", "berthing_12-Nov-2020_11_14_47.csv")
VALIDATION = ("berthing_12-Nov-2020_11_21_46.csv",)
SHORT = {"epochs": 2, "warm_start_epochs": 2}
CASES = {
    "hybrid_D1": ("hybrid_D1.toml", {"training": SHORT}),
    "nn_D1": ("nn_D1.toml", {"training": SHORT}),
    "mmg_identified_D2": ("mmg_identified_D2.toml", {"identify": {"epochs": 2}}),
    "mmg_identified_lm_D2": ("mmg_identified_lm_D2.toml", {"identify": {"iterations": 4}}),
    "hybrid_identified_D2": ("hybrid_identified_D2.toml", {"training": SHORT, "identify": {"epochs": 2}}),
    "hybrid_joint_D2": ("hybrid_identified_D2.toml", {"training": SHORT, "identify": {"stage": "joint"}}),
}
# cases interrupted after their first epoch report and resumed from the checkpoint
RESUMED = {"hybrid_D1_resumed": "hybrid_D1", "hybrid_identified_D2_resumed": "hybrid_identified_D2"}


class _Interrupted(Exception):
    pass


def _plain(value):
    """`value` with floats that are NaN as the string "nan" (equal to themselves) and enum
    members as their values (loadable with ``weights_only=True``)."""
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, float) and math.isnan(value):
        return "nan"
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def run_case(name: str, dataset: Path, root: Path, out: Path) -> dict:
    """One case's results: weights, history (without seconds), summary (without seconds),
    epoch reports, validation horizons, w_v and the last checkpoint's state."""
    import torch
    from sysid.config.experiment import load_experiment
    from sysid.data.recordings import read_runs
    from sysid.identify.trainer import Trainer

    config, changes = CASES[RESUMED.get(name, name)]
    exp = load_experiment(root / "configs" / "experiments" / config)
    exp = exp.replace(**{section: {**values} for section, values in changes.items()})
    if name == "hybrid_joint_D2":
        from sysid.config.choices import Stage
        exp = exp.replace(identify={"stage": Stage.JOINT})
    berthing = dataset / "berthing"
    runs, validation = read_runs([berthing / f for f in TRAIN]), read_runs([berthing / f for f in VALIDATION])
    reports: list = []
    checkpoint = out / f"{name}.ckpt.pt"

    def report(r) -> None:
        reports.append([r.stage, r.epoch, r.epochs, r.train_loss, r.val_loss, r.best_loss, r.best_epoch])
        if name in RESUMED and len(reports) == 1:
            raise _Interrupted

    if name in RESUMED:
        try:
            Trainer(exp, progress=False, log=lambda _: None, checkpoint=checkpoint, on_epoch=report).fit(runs, validation)
        except _Interrupted:
            pass
    trainer = Trainer(exp, progress=False, log=lambda _: None, checkpoint=checkpoint, on_epoch=report,
                      resume=name in RESUMED)
    trainer.fit(runs, validation)
    summary = trainer.summary_.to_dict()
    summary.pop("train_seconds")
    history = trainer.history_.drop(columns="seconds").to_dict("list")
    saved = torch.load(checkpoint, weights_only=True) if checkpoint.is_file() else {}
    if saved:  # the state the file holds as the package reads it back (its file layout's version apart)
        from sysid.identify.checkpoint import CheckpointState
        saved = {"config": saved["config"], **CheckpointState.from_state_dict(saved, checkpoint).to_state_dict()}
    for row in saved.get("stage_history", []) + saved.get("history", []):
        row.pop("seconds")
    saved.get("summary", {}).pop("train_seconds", None)
    return {"weights": trainer.model_.state_dict(), "history": _plain(history), "summary": _plain(summary),
            "reports": _plain(reports), "horizons": list(trainer.validation_sets_),
            "w_v": trainer.velocity_weights_, "checkpoint": saved}


def _autograd_gradient(self, z, target_T, loss: bool = False):
    """`OneStepRegression.gradient` through autograd on the network's own layers: the one-piece
    trainer's forward pass and backward, its gradients copied into the flat ``grad``."""
    import torch
    from sysid.identify.losses import weight_norm
    net = self.net
    with torch.no_grad():
        for q, v in zip(self.parameters, self.views):
            q.copy_(v)
    net.zero_grad()
    with torch.enable_grad():
        value = ((net.layers(z)[0] - target_T.T) ** 2).mean() + self.lambda_L2 * weight_norm(net)
        value.backward()
    for d, q in zip(self.grads, self.parameters):
        d.copy_(q.grad)
    return value.detach() if loss else None


def main(dataset: str, root: str, out: str, *names: str) -> None:
    import torch
    from sysid.device import compute_threads
    import sysid
    from sysid.hybrid import force_models
    if hasattr(force_models.CorrectedModel, "training_rate"):
        # every case through autograd, as the one-piece trainer trained: this compares the
        # trainer's parts; the MMG's hand-derived VJP (the training default, equal to round-off,
        # not bit for bit) is compared with autograd in tests/mmg/test_vjp.py
        force_models.CorrectedModel.training_rate = lambda self, per_member=False: None
    import importlib.util
    if importlib.util.find_spec("sysid.identify.warm_start") is not None:  # not in the one-piece trainer
        from sysid.identify import warm_start
        if hasattr(warm_start, "OneStepRegression"):
            # the warm start's gradient through autograd, as the one-piece trainer computed it; the
            # closed-form gradient (equal to round-off) is compared with autograd in
            # tests/identify/test_warm_start.py, and its flat Adam is torch's to the bit
            warm_start.OneStepRegression.gradient = _autograd_gradient
    import contextlib
    native_off = contextlib.nullcontext()
    if importlib.util.find_spec("sysid.mmg.native") is not None:  # not in the one-piece trainer
        from sysid.mmg import native
        # the MMG's no-grad forwards (losses, evaluation) through torch, as the one-piece trainer
        # computed them; the native kernel (equal to round-off) is compared with the torch path
        # in tests/mmg/test_native.py and tests/maneuvers/test_simulation.py
        native_off = native.torch_path()
    results = {"package": sysid.__file__}
    with compute_threads(1), native_off:
        for name in names or [*CASES, *RESUMED]:
            results[name] = run_case(name, Path(dataset), Path(root), Path(out).parent)
    torch.save(results, out)


if __name__ == "__main__":
    main(*sys.argv[1:])
