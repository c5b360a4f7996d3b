"""A standard-MMG ship written from scratch: a 4 m tanker model, every value invented for
the tests (the KVLCC2 derivatives); `simulated_logs`: processed logs of it with known
derivatives."""
import math

import numpy as np
import torch

SCRATCH = """
[ship]
name = "scratch_tanker"

[principal]
L_pp = 4.0
B = 0.72
d = 0.26
rho = 1000.0

[mass]
m = 600.0
m_x = 45.76
m_y = 463.84
I_zz_J_zz = 1100.0
x_G = 0.14

[hull]
model = "standard"
R_0 = 0.022
X_vv = -0.040
X_vr = 0.002
X_rr = 0.011
X_vvvv = 0.771
Y_v = -0.315
Y_r = 0.083
Y_vvv = -1.607
Y_vvr = 0.379
Y_vrr = -0.391
Y_rrr = 0.008
N_v = -0.137
N_r = -0.049
N_vvv = -0.030
N_vvr = -0.294
N_vrr = 0.055
N_rrr = -0.013

[propeller]
model = "standard"
D = 0.12
t_P = 0.22
w_P0 = 0.40
x_P = -0.48
k0 = 0.2931
k1 = -0.2753
k2 = -0.1385
C_1 = 2.0
C_2_plus = 1.6
C_2_minus = 1.1

[rudder]
model = "standard"
A_R = 0.0176
H_R = 0.19
f_alpha = 2.747
epsilon = 1.09
kappa = 0.5
x_R = -0.5
l_R = -2.84
gamma_R_minus = 0.395
gamma_R_plus = 0.640
t_R = 0.387
a_H = 0.312
x_H = -1.856

[sensors]
gnss_fore = [1.6, 0.0]
gnss_aft = [-1.6, 0.0]
gnss_baseline = 3.2
heading_offset = 0.0
anemometer_1 = [1.2, 0.0]
anemometer_2 = [-0.8, 0.0]
fog = [0.0, 0.0]
"""


def simulated_logs(ship_path, folder, truth: dict[str, float], seconds: float = 150.0) -> list:
    """Three processed logs (turn.csv, zigzag.csv, random.csv in `folder`, 1 Hz, `seconds`
    long, 14 rps) of the ship file `ship_path`'s MMG with the coefficients `truth`
    replacing the file's: the "measured" runs identification has a truth to move towards."""
    from sysid import MMG, integrate, load_ship
    from processed_runs import write_processed_csv

    model = MMG(load_ship(ship_path, truth))
    paths = []
    for name, law in {"turn": lambda t: math.radians(30) * (t > 5),
                      "zigzag": lambda t: math.radians(15) * np.sign(np.sin(2 * math.pi * t / 50) + 1e-9),
                      "random": lambda t: math.radians(25) * np.sin(t / 7.0) * np.cos(t / 23.0)}.items():
        t = np.arange(0.0, seconds, 1.0)
        inputs = np.zeros((len(t), 4))
        inputs[:, 0], inputs[:, 1] = 14.0, [law(s) for s in t]   # n [rps], delta [rad]
        x0 = torch.tensor([0.0, 0.9, 0.0, 0.0, 0.0, 0.0], dtype=torch.float64)
        states = integrate(model, x0, torch.tensor(inputs), 1.0, "rk4").numpy()
        paths.append(write_processed_csv(folder / f"{name}.csv", t, states, inputs))
    return paths
