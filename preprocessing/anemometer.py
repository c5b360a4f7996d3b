"""Wind: anemometer apparent wind -> local true wind -> averaged true wind -> relative wind.

Directions are *from* directions: apparent ones from the bow towards starboard, true ones
from x0 (north) towards y0 (east), all in [0, 2 pi). The air velocity seen by a sensor at
body point p is the true wind minus the sensor's velocity, which is the midship velocity
(u, v_m) plus r x p = (-r p_y, r p_x) in the body frame.
"""
from __future__ import annotations

import numpy as np

from preprocessing.frames import body_to_earth, earth_to_body, flow_velocity, from_direction


def true_wind_from_sensor(speed, direction, u, v, r, psi, position):
    """Earth-frame true wind velocity (vx, vy) [m/s] from one anemometer, arrays (N,)."""
    ax, ay = flow_velocity(speed, direction)          # apparent air velocity, body frame
    px, py = position
    bx, by = ax + (u - r * py), ay + (v + r * px)     # + sensor velocity -> true, body
    return body_to_earth(psi, bx, by)


def apparent_at(true_vx, true_vy, u, v, r, psi, position):
    """Apparent wind (speed [m/s], from-direction [rad]) at body point `position`."""
    bx, by = earth_to_body(psi, true_vx, true_vy)
    px, py = position
    return from_direction(bx - (u - r * py), by - (v + r * px))


def combine(sensors, u, v, r, psi, positions):
    """Averaged true wind and the relative wind at midship.

    sensors : [(speed, direction), ...] per anemometer; positions : matching body (x, y).
    Returns (U_T, gamma_T, U_A, gamma_A), each (N,).
    """
    vx = np.zeros_like(u)
    vy = np.zeros_like(u)
    for (speed, direction), pos in zip(sensors, positions):
        ex, ey = true_wind_from_sensor(speed, direction, u, v, r, psi, pos)
        vx, vy = vx + ex, vy + ey
    vx, vy = vx / len(sensors), vy / len(sensors)
    speed_t, dir_t = from_direction(vx, vy)
    speed_a, dir_a = apparent_at(vx, vy, u, v, r, psi, (0.0, 0.0))
    return speed_t, dir_t, speed_a, dir_a
