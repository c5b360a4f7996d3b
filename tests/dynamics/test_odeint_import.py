"""`sysid.dynamics.odeint`: torchdiffeq's own `odeint`, imported without scipy; its
"scipy_solver" still there, scipy imported when it is chosen. Each case in a fresh process."""
import subprocess
import sys

import pytest

EULER_AND_SCIPY = """
import math, sys, torch
{first}
from sysid.dynamics.odeint import odeint
import torchdiffeq
print("same function:", odeint is torchdiffeq.odeint)
print("scipy before:", any(m.split(".")[0] == "scipy" for m in sys.modules))
# dx/dt = -x from x = 1 with steps of 0.25: Euler gives (1 - 0.25)^n exactly in float64
t = torch.arange(5, dtype=torch.float64) * 0.25
x = odeint(lambda t, x: -x, torch.ones(1, dtype=torch.float64), t, method="euler")
print("euler exact:", all(x[n, 0].item() == 0.75 ** n for n in range(5)))
x = odeint(lambda t, x: -x, torch.ones(1, dtype=torch.float64), torch.tensor([0.0, 1.0], dtype=torch.float64),
           method="scipy_solver", options={{"solver": "RK45"}}, rtol=1e-11, atol=1e-13)
print("scipy_solver error:", abs(x[1, 0].item() - math.exp(-1.0)))
print("scipy after:", "scipy.integrate" in sys.modules)
"""


def _run(first: str) -> dict[str, str]:
    done = subprocess.run([sys.executable, "-W", "ignore", "-c", EULER_AND_SCIPY.format(first=first)],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    return dict(line.split(": ", 1) for line in done.stdout.strip().splitlines())


@pytest.mark.parametrize("first, scipy_before", [("", "False"), ("import torchdiffeq", "True")])
def test_odeint_is_torchdiffeqs_own_and_loads_scipy_only_for_its_scipy_solver(first, scipy_before):
    """Fresh: no scipy until "scipy_solver" runs; torchdiffeq imported before: left as it is."""
    out = _run(first)
    assert out["same function"] == "True"
    assert out["scipy before"] == scipy_before
    assert out["euler exact"] == "True"
    assert float(out["scipy_solver error"]) < 1e-9  # e^-1 by scipy's RK45 through torchdiffeq
    assert out["scipy after"] == "True"
