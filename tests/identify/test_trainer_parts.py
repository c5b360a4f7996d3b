"""The trainer in parts (`sysid.identify`: the training loop, its checkpointing and logging,
the identification strategies) gives what the one-piece trainer of commit `BEFORE` gave:
on tiny real-data cases (hybrid D1, NN D1, the MMG identified by gradient and by
Levenberg-Marquardt, a hybrid on identified and on jointly identified coefficients, two
resumed runs) the same weights (`torch.equal`), the same history rows, summary, epoch
reports and checkpoint, and the same ``val_loss_multistep``. Both versions run
`tests/support/trainer_cases.py` in a subprocess with one torch thread on the experiment
configs of `BEFORE`; the earlier one is ``git archive BEFORE sysid`` of this repository.
A change meant to alter the trainer's numbers moves `BEFORE` to its own commit."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[2]
# the identification through the coefficients' VJP (idvjp, c60db44) and NN-only's training right-hand side
# (nnfast: nn_D1's losses move at 1e-7 relative, round-off; the other cases as c60db44's); d473cdc: the
# one-piece trainer
BEFORE = "0e74096c84c2d784f6868f593a778cc70827c51e"
SCRIPT = ROOT / "tests" / "support" / "trainer_cases.py"


def _results(package_root: Path, configs_root: Path, dataset_dir: Path, out: Path) -> dict:
    out.parent.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "PYTHONPATH": str(package_root), "SYSID_DATA": str(dataset_dir)}
    subprocess.run([sys.executable, str(SCRIPT), str(dataset_dir), str(configs_root), str(out)], check=True, env=env,
                   cwd=out.parent)
    results = torch.load(out, weights_only=True)
    assert Path(results.pop("package")).resolve() == (package_root / "sysid" / "__init__.py").resolve()
    return results


def _differences(a, b, where: str = "") -> list[str]:
    """Where `a` and `b` differ (tensors: `torch.equal`, with dtype and shape)."""
    if isinstance(a, torch.Tensor) or isinstance(b, torch.Tensor):
        same = (isinstance(a, torch.Tensor) and isinstance(b, torch.Tensor) and a.dtype == b.dtype
                and a.shape == b.shape and bool(torch.equal(a, b)))
        return [] if same else [where]
    if isinstance(a, dict) and isinstance(b, dict):
        if list(a) != list(b):
            return [f"{where}: keys {sorted(set(a) ^ set(b))}"]
        return [d for k in a for d in _differences(a[k], b[k], f"{where}.{k}")]
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        if len(a) != len(b):
            return [f"{where}: length {len(a)} != {len(b)}"]
        return [d for i, (x, y) in enumerate(zip(a, b)) for d in _differences(x, y, f"{where}[{i}]")]
    return [] if (type(a) is type(b) and a == b) else [f"{where}: {a!r} != {b!r}"]


def _keys(text: str) -> set[tuple[str, str]]:
    """(section, key) of every line ``key = value`` of a resolved config's TOML text."""
    found, section = set(), ""
    for line in text.splitlines():
        if line.startswith("["):
            section = line
        elif " = " in line:
            found.add((section, line.split(" = ", 1)[0]))
    return found


def _known_keys(text: str, before: str) -> str:
    """The resolved config `text` without the lines of keys the resolved config `before` lacks
    (keys added since, which the older package cannot write)."""
    known, section, kept = _keys(before), "", []
    for line in text.splitlines():
        section = line if line.startswith("[") else section
        if " = " not in line or (section, line.split(" = ", 1)[0]) in known:
            kept.append(line)
    return "\n".join(kept) + ("\n" if text.endswith("\n") else "")


def test_trainer_in_parts_gives_the_one_piece_trainers_results(dataset_dir, tmp_path):
    before = tmp_path / "before"
    before.mkdir()
    # the package and the experiment configs of BEFORE: both versions train the same configs
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", BEFORE, "sysid", "configs"], check=True,
                             capture_output=True)
    subprocess.run(["tar", "-x", "-C", str(before)], input=archive.stdout, check=True)
    old = _results(before, before, dataset_dir, tmp_path / "old" / "results.pt")
    new = _results(ROOT, before, dataset_dir, tmp_path / "new" / "results.pt")
    assert list(new) == list(old) and len(old) == 8
    for case in old:
        if "config" in new[case]["checkpoint"]:   # config keys added after BEFORE, at their defaults
            new[case]["checkpoint"]["config"] = _known_keys(new[case]["checkpoint"]["config"],
                                                            old[case]["checkpoint"]["config"])
        assert _differences(new[case], old[case], case) == []
        assert new[case]["summary"]["val_loss_multistep"] == old[case]["summary"]["val_loss_multistep"]
    # the cases do what they say: training stages, an LM fit, a resumed run
    assert old["mmg_identified_lm_D2"]["summary"]["identification"]["solver"] == "levenberg_marquardt"
    assert old["hybrid_identified_D2"]["history"]["stage"] == ["identify", "identify", "train", "train"]
    assert old["hybrid_D1_resumed"]["reports"][0][:2] == ["train", 1]
    assert _differences(old["hybrid_D1_resumed"]["weights"], old["hybrid_D1"]["weights"]) == []
