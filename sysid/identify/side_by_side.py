"""Seeds side by side: the training stage of N seeds of one configuration in one process,
their networks stacked on the FNN's member axis.

Each seed is an ordinary `Trainer`: `Trainer.prepare` (split, standardisation, warm start,
or a checkpoint) and `Trainer.finish` (gate, validation loss) run per seed as when it trains
alone. Only stage 5, the multi-step training, is shared: one Euler rollout per minibatch for
the members of every seed still training (through the hybrid's training right-hand side,
`integrate_training`, as a seed alone), each seed on its own windows (its own batch
order, drawn with its own generator), the loss summed over seeds so that each seed's slice
of the gradient is its solo gradient, and Adam applied per member (Adam is elementwise, so
the stacked update is each seed's own). A seed that stops early leaves the stack: its
parameters and optimizer state no longer change. Each seed writes its own checkpoint in the
solo layout, so it resumes side by side or alone. The trained model of each seed equals the
one trained alone to round-off.

The seeds must share everything but their seed: windows, MMG and standardisation.
`refusal` says why a configuration's seeds cannot (validation blocks are drawn with the
seed; identified MMG coefficients are one set per seed).
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
import torch

from sysid.config.choices import ModelKind, Validation
from sysid.config.experiment import Experiment
from sysid.data.recordings import Run
from sysid.dynamics.equations import integrate_loss, integrate_training
from sysid.dynamics.rollouts import WindowSet
from sysid.errors import ConfigError, TrainingError
from sysid.hybrid.correction import ForceCorrection
from sysid.hybrid.force_models import CorrectedModel, PerMember
from sysid.identify.losses import VEL, output_penalty
from sysid.identify.loop import StageResult, StageState
from sysid.identify.trainer import Prepared, Trainer

LABEL = "train"
_LOG = logging.getLogger(__name__)


def refusal(exp: Experiment, validation_logs: bool = False) -> str | None:
    """Why the seeds of `exp` cannot train side by side (None: they can); `validation_logs`:
    validation logs are given (as ``Trainer.fit``'s `validation`)."""
    if exp.experiment.model is ModelKind.MMG:
        return "an MMG-only model has no network to stack"
    if exp.identify.parameters:
        return "[identify] parameters: the identified MMG coefficients are one set per seed"
    if exp.training.validation is Validation.BLOCKS and not (exp.data.validation or validation_logs):
        return ("[training] validation = \"blocks\": the validation blocks are drawn with the seed, so the "
                "seeds train on different windows")
    return None


@dataclass(eq=False)
class _Seed:
    """One seed's training stage: its trainer, prepared stages 1-4 and the loop's
    `StageState` (its solo optimizer in the checkpoint's layout, with the learning rate and
    Adam state between epochs; schedule, minibatch generator, early-stopping record)."""

    trainer: Trainer
    prepared: Prepared
    state: StageState

    @property
    def net(self) -> ForceCorrection:
        model = self.prepared.model
        assert model is not None
        return model.correction_net

    @property
    def params(self) -> list[torch.nn.Parameter]:
        return list(self.net.parameters())


def _same(a: torch.Tensor, b: torch.Tensor) -> bool:
    return a.shape == b.shape and bool(torch.equal(a, b))


def _check_shared(seeds: Sequence[_Seed]) -> None:
    """The seeds share windows, w_v, MMG and standardisation (else one `ConfigError` line)."""
    first = seeds[0].prepared
    ref_mmg = first.mmg.state_dict()
    ref_buffers = dict(seeds[0].net.named_buffers())
    for seed in seeds[1:]:
        p = seed.prepared
        same = (_same(p.train.states, first.train.states) and _same(p.val.states, first.val.states)
                and _same(p.train.inputs, first.train.inputs) and _same(p.val.inputs, first.val.inputs)
                and _same(p.w_v, first.w_v)
                and all(_same(v, ref_mmg[k]) for k, v in p.mmg.state_dict().items())
                and all(_same(v, ref_buffers[k]) for k, v in seed.net.named_buffers()))
        if not same:
            raise ConfigError(f"{seed.trainer.experiment.source or 'experiment'}: seed "
                              f"{seed.trainer.experiment.experiment.seed} does not share the windows, MMG and "
                              "standardisation of the first seed; train its seeds one by one")


class _Stack:
    """The active seeds' networks as one `ForceCorrection` (members seed by seed) with
    their Adam moments, built from the seeds' own networks and optimizers, and written
    back to them."""

    def __init__(self, seeds: Sequence[_Seed], template: CorrectedModel):
        self.seeds = list(seeds)
        net0 = seeds[0].net
        self.per_seed = net0.members
        net = ForceCorrection([w.shape[2] for w in net0.weights][:-1], net0.input_mean.dtype,
                              self.per_seed * len(seeds)).to(net0.input_mean.device)
        with torch.no_grad():
            for name, buffer in net0.named_buffers():
                getattr(net, name).copy_(buffer)
            for i, p in enumerate(net.parameters()):
                p.copy_(torch.cat([list(s.net.parameters())[i] for s in seeds]))
        self.net = net
        self.model = PerMember(CorrectedModel(template.mmg, net, None, physics=template.physics,
                                              gate_space=template.gate_space))
        self.exp_avg = [torch.zeros_like(p) for p in net.parameters()]
        self.exp_avg_sq = [torch.zeros_like(p) for p in net.parameters()]
        for i in range(len(self.exp_avg)):
            for k, s in enumerate(seeds):
                state = s.state.optimizer.state.get(s.params[i])
                if state:
                    self._slice(self.exp_avg[i], k).copy_(state["exp_avg"])
                    self._slice(self.exp_avg_sq[i], k).copy_(state["exp_avg_sq"])
        self.steps = [float(s.state.optimizer.state[s.params[0]]["step"]) if s.state.optimizer.state.get(s.params[0]) else 0.0
                      for s in seeds]

    def _slice(self, tensor: torch.Tensor, k: int) -> torch.Tensor:
        return tensor[k * self.per_seed:(k + 1) * self.per_seed]

    def _per_member(self, values: Sequence[float], like: torch.Tensor) -> torch.Tensor:
        """(K, 1, ...) of one number per seed, repeated over its members."""
        column = torch.tensor(values, dtype=like.dtype, device=like.device).repeat_interleave(self.per_seed)
        return column.reshape(-1, *([1] * (like.dim() - 1)))

    @torch.no_grad()
    def step(self) -> None:
        """One Adam step of every member (torch's Adam: betas, eps and lr of each seed's
        optimizer, no weight decay), each with its seed's step count."""
        self.steps = [n + 1.0 for n in self.steps]
        groups = [s.state.optimizer.param_groups[0] for s in self.seeds]
        beta1, beta2 = groups[0]["betas"]
        eps = groups[0]["eps"]
        step_size = [-g["lr"] / (1 - beta1 ** n) for g, n in zip(groups, self.steps)]
        bias2_sqrt = [(1 - beta2 ** n) ** 0.5 for n in self.steps]
        columns: dict[int, tuple[torch.Tensor, torch.Tensor]] = {}  # by the parameter's dim
        for p, m, v in zip(self.net.parameters(), self.exp_avg, self.exp_avg_sq):
            g = p.grad
            m.lerp_(g, 1 - beta1)
            v.mul_(beta2).addcmul_(g, g, value=1 - beta2)
            if p.dim() not in columns:
                columns[p.dim()] = (self._per_member(bias2_sqrt, v), self._per_member(step_size, p))
            bias2, size = columns[p.dim()]
            denom = (v.sqrt() / bias2).add_(eps)
            p.add_(size * m / denom)

    @torch.no_grad()
    def write_back(self) -> None:
        """Each seed's slice of parameters and Adam moments into its own network and
        optimizer (the checkpoint's and the resumed run's layout)."""
        stacked = list(self.net.parameters())
        for k, s in enumerate(self.seeds):
            for i, p in enumerate(s.params):
                p.copy_(self._slice(stacked[i], k))
                s.state.optimizer.state[p] = {"step": torch.tensor(self.steps[k]),
                                        "exp_avg": self._slice(self.exp_avg[i], k).clone(),
                                        "exp_avg_sq": self._slice(self.exp_avg_sq[i], k).clone()}


def _losses(stack: _Stack, batch: WindowSet, w_v: torch.Tensor, w_F: torch.Tensor | None, band: float):
    """Per seed (N,) L_v, L_F and |theta|^2 of its members on its own windows: `batch` holds
    (T+1, N, B, ·), seed k's windows at [:, k]."""
    k, m = len(stack.seeds), stack.per_seed
    states, inputs = (x.unsqueeze(2).expand(x.shape[0], k, m, *x.shape[2:]).reshape(x.shape[0], k * m, *x.shape[2:])
                      for x in (batch.states, batch.inputs))
    if w_F is None:  # no forces kept (validation; NN-only's training: its training right-hand side)
        predicted = integrate_loss(stack.model, states[0], inputs, batch.dt)
    else:  # the members' training right-hand side (`integrate_training`), as a seed alone trains
        predicted, f_nn, f_mmg = integrate_training(stack.model, states[0], inputs, batch.dt)
    err = predicted[1:, ..., VEL] - states[1:, ..., VEL]
    loss_v = ((err * err) * w_v).sum(-1).mean((0, 2)).reshape(k, m).mean(1)
    if w_F is None:
        loss_F = torch.zeros_like(loss_v)
    else:
        loss_F = output_penalty(f_nn, f_mmg, w_F, band).mean((0, 2)).reshape(k, m).mean(1)
    l2 = sum((w * w).flatten(1).sum(1) for w in stack.net.weights).reshape(k, m).sum(1) / m
    return loss_v, loss_F, l2


def _val_losses(stack: _Stack, val: WindowSet, w_v: torch.Tensor) -> list[float]:
    """Each seed's validation velocity loss L_v (its members' mean), as `multistep_loss`."""
    k = len(stack.seeds)
    index = torch.arange(len(val), device=val.states.device).expand(k, len(val))
    with torch.no_grad():
        batch = WindowSet(val.states[:, index], val.inputs[:, index], val.dt)
        return _losses(stack, batch, w_v, None, 0.0)[0].tolist()


def _start(trainer: Trainer, prepared: Prepared) -> _Seed:
    """A seed's training stage as the trainer's loop starts it (or resumes it); a resumed
    stage that had stopped stays stopped."""
    t = trainer.experiment.training
    model = prepared.model
    assert model is not None
    state = trainer.loop.start(PerMember(model), prepared.params, t.learning_rate, LABEL)
    if trainer.checkpointing.stage(LABEL) is not None:
        if state.epoch - state.best_epoch >= t.patience:
            state.stopped = "early stop"
        elif state.epoch >= t.epochs:
            state.stopped = "epoch limit"
    return _Seed(trainer, prepared, state)


class _InGroupLine:
    """A seed's epoch progress is shown in its group's line (`progress_line`), not on its
    own: the loop's progress bar that shows nothing."""

    def set_postfix(self, **losses) -> None:
        return None


def _end_epoch(seed: _Seed, model: PerMember, train_sums: np.ndarray, val_v: float, seconds: float) -> None:
    """The loop's bookkeeping after an epoch (history, best state, schedule, stopping,
    checkpoint, `EpochReport`; progress in the group's line), and the epoch limit."""
    t = seed.trainer.experiment.training
    seed.trainer.loop.end_epoch(seed.state, model, LABEL, t.epochs, train_sums, val_v, seconds, _InGroupLine())
    if seed.state.stopped is None and seed.state.epoch >= t.epochs:
        seed.state.stopped = "epoch limit"


def _result(seed: _Seed) -> StageResult:
    """The loop's end of a stage: the best state restored, a hit time limit, the log line."""
    model = seed.prepared.model
    assert model is not None
    return seed.trainer.loop.end_stage(PerMember(model), LABEL, seed.state)


def progress_line(seeds: Sequence[_Seed]) -> str:
    """One line for the group: each seed's epoch, early-stopping loss and best epoch, or
    why it stopped."""
    total = seeds[0].trainer.experiment.training.epochs
    parts = []
    for s in seeds:
        st = s.state
        last = f" {st.history[-1]['early_stopping_loss']:.5f}" if st.history else ""
        state = f"{st.stopped} at epoch {st.epoch}" if st.stopped else f"epoch {st.epoch}{last}"
        parts.append(f"seed {s.trainer.experiment.experiment.seed} {state} (best {st.best_epoch})")
    active = sum(s.state.stopped is None for s in seeds)
    return f"{LABEL}: {active}/{len(seeds)} seeds training, of {total} epochs: " + "; ".join(parts)


def train_side_by_side(seeds: Sequence[_Seed], log: Callable[[str], None] | None = None) -> list[StageResult]:
    """Stage 5 of every seed at once (see the module); each seed's `StageResult`. `log`
    receives one `progress_line` every 10th epoch and whenever a seed stops (None: the
    first seed's log when it shows progress; every epoch's line at DEBUG)."""
    first = seeds[0]
    t = first.trainer.experiment.training
    p = first.prepared
    assert p.model is not None
    train, val, w_v, w_F = p.train, p.val, p.w_v, p.w_F
    if log is None:
        log = first.trainer.journal.line if first.trainer.progress else _LOG.debug
    stack = None
    rounds = 0
    while active := [s for s in seeds if s.state.stopped is None]:
        if stack is None or [id(s) for s in stack.seeds] != [id(s) for s in active]:
            if stack is not None:
                stack.write_back()
            stack = _Stack(active, p.model)
        started = time.perf_counter()
        orders = torch.stack([torch.randperm(len(train), generator=s.state.generator) for s in active])
        sums = np.zeros((len(active), 3))
        for lo in range(0, len(train), t.batch_size):
            batch = train.select(orders[:, lo:lo + t.batch_size])
            loss_v, loss_F, l2 = _losses(stack, batch, w_v, w_F, t.force_band)
            loss = t.lambda_v * loss_v + t.lambda_F * loss_F + t.lambda_L2 * l2
            if not bool(torch.isfinite(loss).all()):
                bad = active[int((~torch.isfinite(loss)).nonzero()[0])]
                raise TrainingError(f"{bad.trainer.experiment.source}: [training] the {LABEL} loss of seed "
                                    f"{bad.trainer.experiment.experiment.seed} became non-finite at epoch "
                                    f"{bad.state.epoch + 1} (learning_rate = {t.learning_rate:g}?); no run written")
            stack.net.zero_grad()
            loss.sum().backward()
            stack.step()
            sums += batch.states.shape[2] * torch.stack((loss, loss_v, loss_F), 1).detach().cpu().numpy()
        val_v = _val_losses(stack, val, w_v)
        sums /= len(train)
        stack.write_back()
        seconds = time.perf_counter() - started
        for k, s in enumerate(active):
            s.state.epoch += 1
            model = s.prepared.model
            assert model is not None
            _end_epoch(s, PerMember(model), sums[k], val_v[k], seconds)
        rounds += 1
        if rounds % 10 == 0 or any(s.state.stopped for s in active):
            log(progress_line(seeds))
        else:
            _LOG.debug(progress_line(seeds))
    return [_result(s) for s in seeds]


def fit_side_by_side(trainers: Sequence[Trainer], runs: Sequence[Run],
                     validation: Sequence[Run] = (), log: Callable[[str], None] | None = None) -> list[Trainer]:
    """`Trainer.fit` of each trainer (the seeds of one configuration: experiments equal but
    for ``[experiment] seed``), their training stages side by side in this process. Each
    trainer keeps its checkpoint, resume flag, log and ``on_epoch``; each comes back fitted
    as if it had trained alone; `log` takes the group's progress lines (`train_side_by_side`).
    One `ConfigError` line when they cannot share (`refusal`)."""
    if not trainers:
        return []

    def but_seed(exp: Experiment) -> str:  # the run's name (a sweep's names its seed) does not train
        return exp.replace(experiment={"seed": 0, "name": "seeds"}).to_toml()

    reference = but_seed(trainers[0].experiment)
    for trainer in trainers:
        exp = trainer.experiment
        if (why := refusal(exp, bool(validation))) is not None:
            raise ConfigError(f"{exp.source or 'experiment'}: seeds cannot train side by side: {why}")
        if but_seed(exp) != reference:
            raise ConfigError(f"{exp.source or 'experiment'}: seeds side by side need one configuration; "
                              f"seed {exp.experiment.seed}'s differs in more than its seed and name")
    seeds = []
    for trainer in trainers:
        prepared = trainer.prepare(runs, validation)
        if not prepared.trains:  # failed before training (cannot happen without [identify])
            raise TrainingError(f"{trainer.experiment.source}: seed {trainer.experiment.experiment.seed} "
                                "has no training stage")
        seeds.append(_start(trainer, prepared))
    _check_shared(seeds)
    stages = train_side_by_side(seeds, log)
    return [s.trainer.finish(s.prepared, stage) for s, stage in zip(seeds, stages)]
