"""`sysid --help` answers at once: the CLI imports no heavy module before a command needs it."""
from __future__ import annotations

import subprocess
import sys

HEAVY = ("torch", "torchdiffeq", "pandas", "scipy", "matplotlib", "filterpy")


def test_the_cli_imports_no_heavy_module_until_a_command_runs():
    code = ("import sys, sysid.cli\n"
            "from sysid.cli import app\n"
            f"print(' '.join(m for m in {HEAVY!r} if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == ""


def test_help_texts_keep_their_bracketed_units():
    done = subprocess.run([sys.executable, "-m", "sysid", "simulate", "--help"], capture_output=True, text=True,
                          env={"COLUMNS": "200", "PATH": ""})
    assert done.returncode == 0, done.stderr
    for unit in ("[s]", "[Hz]"):
        assert unit in done.stdout


def test_train_runs_without_importing_the_compiler(dataset_dir, tmp_path):
    """A whole `sysid train` (warm start, Adam steps, the plateau schedule, gate, verdict,
    run written) in a fresh process never imports torch's compiler stack."""
    from tiny_experiment import tiny_experiment

    config = tiny_experiment(tmp_path / "tiny.toml", dataset_dir, seed=3, epochs=2, warm_start_epochs=2,
                             patience=None)
    config.write_text(config.read_text().replace("[training]\n", "[training]\nlr_factor = 0.5\nlr_patience = 0\n", 1))
    code = ("import sys\nfrom sysid.cli import run\n"
            f"run(['-q', 'train', {str(config)!r}, '-o', {str(tmp_path / 'run')!r}, '--threads', '1'])\n"
            "import gc\nprint('collector:', gc.isenabled(), gc.get_freeze_count() > 0)\n"
            "print('imported:', *(m for m in ('torch._dynamo', 'torch._inductor', 'sympy') if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    assert (tmp_path / "run" / "summary.json").is_file()
    assert done.stdout.strip().splitlines()[-1] == "imported:", done.stdout
    # the training stack was imported with the collector paused, then frozen; the collector runs again
    assert done.stdout.strip().splitlines()[-2] == "collector: True True", done.stdout


def test_train_leaves_the_collector_alone_when_the_stack_is_already_imported():
    """In a process that has imported the training stack already (a test session, an
    embedding), `sysid train`'s import step neither pauses nor freezes anything."""
    import gc

    import sysid.runs.lifecycle  # noqa: F401
    from sysid.cli.train_commands import _import_training

    frozen, enabled = gc.get_freeze_count(), gc.isenabled()
    _import_training()
    assert (gc.get_freeze_count(), gc.isenabled()) == (frozen, enabled)
