"""The logging part of training: every line the training stages say, through one channel.

Lines go to the ``log`` callable a caller gives (`sysid.logs.indented`, a sweep's log) or,
without one, to this module's `logging` logger (``sysid.identify.journal``: INFO, shown by
``sysid``'s handlers, time-stamped when stdout is a file). Progress of the epochs goes
through `sysid.progress` on a terminal (a bar with the losses); in a file or a pipe through a
line every 10 epochs instead, and every epoch at DEBUG (``sysid -v``). Nothing here trains.
"""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Callable, Iterable

from sysid import progress as progress_bars

_LOG = logging.getLogger(__name__)


class TrainingJournal:
    """The training's log lines and epoch progress.

    log : receives one-line messages (None: this module's logger at INFO).
    progress : show progress (a bar on a terminal, a line every 10 epochs elsewhere).
    """

    def __init__(self, log: Callable[[str], None] | None = None, progress: bool = True):
        self.write: Callable[[str], None] = log if log is not None else _LOG.info
        self.progress = progress

    def line(self, message: str) -> None:
        self.write(message)

    # -- progress --------------------------------------------------------------------
    def epochs(self, epochs: Iterable[int], label: str, total: int, done: int):
        """`epochs` as a bar (`sysid.progress`) on a terminal; elsewhere plain (progress
        then comes as log lines, `epoch`)."""
        if self.progress and progress_bars.on_terminal():
            return progress_bars.progress(epochs, total=total - done, desc=label, unit="epoch")
        return epochs

    def epoch(self, bar, epoch: int, total: int, train_v: float, val_v: float, best_epoch: int) -> None:
        """One finished epoch: the bar's losses, or a line every 10 epochs (every epoch at DEBUG)."""
        line = f"  epoch {epoch}/{total}: training {train_v:.5f}, early-stopping {val_v:.5f} (best at {best_epoch})"
        if hasattr(bar, "set_postfix"):
            bar.set_postfix(train=f"{train_v:.4f}", val=f"{val_v:.4f}", best=best_epoch)
        elif self.progress and (epoch % 10 == 0 or epoch == total):
            self.write(line)
        else:
            _LOG.debug(line.strip())  # every epoch with ``sysid -v``

    def warm_start_begins(self, bar, epochs: int, samples: int) -> None:
        if not hasattr(bar, "set_postfix"):
            self.write(f"warm start: {epochs} epochs of one-step regression on {samples} samples")

    def warm_start_epoch(self, bar, epoch: int, epochs: int, loss: float) -> None:
        """A warm-start epoch (from 1): a line every 25 epochs off a terminal (every epoch at DEBUG)."""
        shown = self.progress and (epoch % 25 == 0 or epoch == epochs)
        if not hasattr(bar, "set_postfix") and (shown or _LOG.isEnabledFor(logging.DEBUG)):
            line = f"  warm start epoch {epoch}/{epochs}: loss {loss:.5f}"
            self.write(line) if shown else _LOG.debug(line.strip())  # every epoch with ``sysid -v``

    # -- stages ----------------------------------------------------------------------
    def split(self, report, train: int, val: int, steps: int) -> None:
        for name in report.dropped_copies:
            self.write(f"left out {name}: an exact copy of the start of another training file")
        self.write(f"{train} training and {val} validation windows of {steps} steps "
                   f"({report.suspect_windows} touching frozen GNSS left out)")
        if report.astern_windows:   # under a one-quadrant propeller: every log with samples outside it
            done = "left out" if report.astern_excluded else "kept ([data] exclude_astern = false)"
            self.write(f"WARNING: {report.astern_windows} windows hold samples with astern revolutions or going "
                       f"astern, outside the ship file's one-quadrant propeller model: {done}; per log: " + "; ".join(
                           f"{f['file']} {f['astern_windows']} windows, {f['astern_samples']} samples"
                           for f in report.files if f.get("astern_samples")))

    def resumed(self, label: str, epoch: int, path: Path | None) -> None:
        self.write(f"{label}: resumed after epoch {epoch} from {path}" if path is not None
                   else f"{label}: resumed after epoch {epoch}")

    def stage_end(self, label: str, stage, failure: str | None) -> None:
        """A stage's end (`sysid.identify.loop.StageResult`), after its failure if it hit the
        wall-clock limit."""
        if failure is not None:
            self.write(f"FAILED: {failure}")
        self.write(f"{label}: {len(stage.history)} epochs, best early-stopping loss {stage.best_loss:.5f} at epoch "
                   f"{stage.best_epoch} ({stage.stopped}; validation windows, before any kNN gate)")

    def identified(self, coefficients: dict[str, float]) -> None:
        self.write("identified: " + ", ".join(f"{k} = {v:.5g}" for k, v in coefficients.items()))

    def uncertainty(self, result) -> None:
        """± 2 sigma of a `sysid.identify.uncertainty.CoefficientUncertainty`."""
        self.write("identified ± 2 sigma: " + ", ".join(
            f"{k} = {e:.4g} ± {2 * s:.2g}" + (" (undetermined)" if u else "")
            for k, e, s, u in zip(result.names, result.estimate, result.std_error, result.undetermined)))

    def least_squares(self, solver) -> None:
        """The fit of a `sysid.identify.solvers.least_squares.LevenbergMarquardtIdentification`."""
        fit = solver.fit_
        rule = solver.estimator_.integrator
        self.write(f"identify: Levenberg-Marquardt, start states {solver.start_states}, {solver.windows_} disjoint "
                   f"windows" + (f" integrated by {rule.upper()}" if rule != "euler" else "")
                   + f", {fit.iterations} iterations ({fit.stopped}); multi-step loss training "
                   f"{solver.train_loss_:.5f}, validation {solver.val_loss_:.5f}")

    def start_state_check(self, check, val_v: float, check_val: float) -> None:
        said = (f"check: {check.verdict()}; validation loss {check_val:.5f} "
                f"(start states {check.start_states}) against {val_v:.5f}")
        self.write(said if check.agrees else "WARNING " + said)

    def mmg_losses(self, train: float, val: float) -> None:
        self.write(f"MMG-only multi-step loss: training {train:.5f}, validation {val:.5f}")

    def warm_started(self, val: float) -> None:
        self.write(f"after warm start: validation loss {val:.5f}")

    def ensemble(self, members: int, val: float) -> None:
        if members > 1:
            self.write(f"mean of {members} networks: validation loss {val:.5f}")

    def gate(self, bank: int, threshold: float) -> None:
        self.write(f"kNN gate: {bank} training features, threshold {threshold:.4f}")

    def horizon_left_out(self, horizon: float, block_s: float | None) -> None:
        """A horizon of ``val_loss_multistep`` without a validation window (`block_s`: the
        validation blocks are shorter; None: the blocks or logs are)."""
        if block_s is not None:
            self.write(f"val_loss_multistep: no validation window of {horizon:g} s fits a {block_s:g}-s "
                       "validation block; that horizon is left out")
        else:
            self.write(f"val_loss_multistep: no validation window of {horizon:g} s (the validation blocks or "
                       "logs are shorter); that horizon is left out")

    def objective(self, value: float, sets: dict, gated: bool, stopping_best: float | None) -> None:
        judged = " and ".join(f"{len(w)} of {h:g} s" for h, w in sets.items())
        self.write(f"val_loss_multistep {value:.5f}: the final model"
                   + (" (kNN gate on)" if gated else "") + f" on validation windows: {judged}"
                   + (f"; the early-stopping loss {stopping_best:.5f} is the network's during training, "
                      "before the gate" if stopping_best is not None else ""))
