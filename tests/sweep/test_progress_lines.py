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


def test_a_retry_line_carries_the_failures_own_first_line():
    """A trial whose delivery the inbox refused fails with Ray's wrapper of the trial's
    exception, itself wrapping the inbox actor's: the retry line says the inbox's message,
    not Ray's "ray::..." header; a failure Tune recorded nothing of keeps the general cause."""
    from ray.exceptions import RayTaskError

    from sysid.errors import IncompleteOutputError

    refused = IncompleteOutputError("trials/base/seed0: the delivered run was trained with another config than "
                                    "its trial's; not kept")
    inner = RayTaskError("Inbox.deliver", "Traceback (most recent call last):\n  ...", refused,
                         proctitle="ray::Inbox", pid=2, ip="10.0.0.2")
    outer = RayTaskError("ImplicitFunc.train", "Traceback (most recent call last):\n  ...", inner,
                         proctitle="ray::ImplicitFunc.train", pid=3, ip="10.0.0.3")
    assert "ray::ImplicitFunc.train()" in str(outer).splitlines()[0]   # Ray's header, not the cause
    said: list[str] = []
    callback = progress_callback(1, lambda c: c["name"], said.append, prefix="sweep")

    def failed(error):
        def pickled():
            if isinstance(error, Exception):
                return error
            raise FileNotFoundError("no error.pkl")
        return SimpleNamespace(trial_id="0", config={"name": "base seed0"}, get_pickled_error=pickled)

    callback.on_trial_start(0, [], failed(None))
    callback.on_trial_recover(0, [], failed(outer))
    assert said[-1] == ("sweep: retrying base seed0 after a failure: trials/base/seed0: the delivered run was trained "
                        "with another config than its trial's; not kept | 0/1 done, 1 running, 0 failed, "
                        "0 stopped early, 1 retried")
    callback.on_trial_recover(0, [], failed(None))
    assert said[-1].startswith("sweep: retrying base seed0 after a failure (a lost node or a crash) | ")
    assert said[-1].endswith(", 2 retried")
