"""The trial progress lines of a sweep name the best trial so far; those of `sysid reproduce
--seeds N`, whose trials are different experiments (D1 and D2, NN-only and hybrid), do not."""
from __future__ import annotations

from types import SimpleNamespace

from sysid.sweep.runner import progress_callback
from sysid.sweep.trial import OBJECTIVE


def lines(rank_trials: bool) -> list[str]:
    said: list[str] = []
    callback = progress_callback(2, lambda c: c["name"], said.append, prefix="x", rank_trials=rank_trials)
    for i, (name, loss) in enumerate((("nn_D1", 0.0647), ("hybrid_D2", 0.0885))):
        trial = SimpleNamespace(trial_id=str(i), config={"name": name}, last_result={"final": True, OBJECTIVE: loss})
        callback.on_trial_start(0, [], trial)
        callback.on_trial_complete(0, [], trial)
    return said

def test_a_sweep_names_its_best_trial_reproduce_does_not():
    assert lines(True)[-1] == ("x: done hybrid_D2 (val_loss_multistep 0.08850) | 2/2 done, 0 running, 0 failed, "
                               "0 stopped early; best val_loss_multistep 0.06470 (nn_D1)")
    assert lines(False)[-1] == "x: done hybrid_D2 (val_loss_multistep 0.08850) | 2/2 done, 0 running, 0 failed, 0 stopped early"
    assert not any("best" in line for line in lines(False))
