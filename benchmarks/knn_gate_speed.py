"""Cost of one kNN OOD-gate query (paper section 3.4.3) on this CPU.

Prints the time per prediction step of d_kNN (k = 10) against banks the size of the D1 and
D2 training sets, in the standardised input space (9-D) and the feature space (64-D), for a
single ship (batch 1) and for all 61 protocol windows of the test files at once; and the
time to fit the gate (leave-one-out distances and threshold).

    python benchmarks/knn_gate_speed.py
"""
from __future__ import annotations

import time

import torch

from sysid.hybrid.knn_gate import KNNGate


def per_call(fn, seconds: float = 0.5) -> float:
    fn()
    calls, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        fn()
        calls += 1
    return (time.perf_counter() - start) / calls


def main() -> None:
    torch.set_num_threads(1)
    g = torch.Generator().manual_seed(0)
    print(f"{'bank':>6} {'dim':>4} {'fit [s]':>8} {'batch 1 [us]':>13} {'batch 61 [us]':>14}")
    for bank_size in (4843, 8545):  # training samples of D1, D2
        for dim in (9, 64):
            bank = torch.randn(bank_size, dim, generator=g)
            start = time.perf_counter()
            gate = KNNGate(10, 0.9995, dim).fit(bank)
            fit_s = time.perf_counter() - start
            one = torch.randn(1, dim, generator=g)
            many = torch.randn(61, dim, generator=g)
            with torch.no_grad():
                t1 = per_call(lambda: gate(one))
                t61 = per_call(lambda: gate(many))
            print(f"{bank_size:>6} {dim:>4} {fit_s:>8.2f} {t1 * 1e6:>13.0f} {t61 * 1e6:>14.0f}")


if __name__ == "__main__":
    main()
