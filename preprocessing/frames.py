"""Frame rotations and angle helpers shared by the steps.

Earth frame: x0 north, y0 east. Body frame: x to the bow, y to starboard. Heading psi
[rad] turns x0 towards y0, so a body vector (bx, by) is, in the earth frame,
(bx cos psi - by sin psi, bx sin psi + by cos psi).
"""
from __future__ import annotations

import numpy as np


def body_to_earth(psi, bx, by):
    """Rotate body-frame components (bx, by) by heading psi [rad]; arrays broadcast."""
    c, s = np.cos(psi), np.sin(psi)
    return bx * c - by * s, bx * s + by * c


def earth_to_body(psi, ex, ey):
    """Inverse of `body_to_earth`."""
    c, s = np.cos(psi), np.sin(psi)
    return ex * c + ey * s, -ex * s + ey * c


def wrap_pi(a):
    """Angle [rad] to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def wrap_2pi(a):
    """Angle [rad] to [0, 2 pi)."""
    return np.mod(a, 2 * np.pi)


def from_direction(vx, vy):
    """Speed and *from* direction [rad, 0..2pi) of a flow with velocity (vx, vy)."""
    return np.hypot(vx, vy), wrap_2pi(np.arctan2(-vy, -vx))


def flow_velocity(speed, from_dir):
    """Velocity (vx, vy) of a flow of `speed` coming *from* `from_dir` [rad]."""
    return -speed * np.cos(from_dir), -speed * np.sin(from_dir)
