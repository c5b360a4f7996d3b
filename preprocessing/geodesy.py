"""WGS-84 latitude/longitude <-> local tangent plane around a reference point.

Local frame: x0 north, y0 east, metres, origin at the reference point on the ellipsoid
(height 0). Exact through ECEF (no flat-earth approximation); the inverse iterates the
geodetic latitude, which converges to < 1e-12 rad in a few steps near the surface.
"""
from __future__ import annotations

import numpy as np

A = 6378137.0                 # m, WGS-84 semi-major axis
F = 1.0 / 298.257223563       # flattening
E2 = F * (2.0 - F)            # first eccentricity squared


def _ecef(lat: np.ndarray, lon: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Geodetic lat, lon [rad] at height 0 -> ECEF X, Y, Z [m]."""
    n = A / np.sqrt(1.0 - E2 * np.sin(lat) ** 2)
    return n * np.cos(lat) * np.cos(lon), n * np.cos(lat) * np.sin(lon), n * (1.0 - E2) * np.sin(lat)


def latlon_to_local(lat_deg, lon_deg, ref_lat_deg: float, ref_lon_deg: float):
    """Lat/lon [deg], arrays of shape (N,) -> (x0 north, y0 east) [m], each (N,)."""
    lat, lon = np.radians(np.asarray(lat_deg, float)), np.radians(np.asarray(lon_deg, float))
    lat0, lon0 = np.radians(ref_lat_deg), np.radians(ref_lon_deg)
    x, y, z = _ecef(lat, lon)
    x_0, y_0, z_0 = _ecef(np.array(lat0), np.array(lon0))
    dx, dy, dz = x - x_0, y - y_0, z - z_0
    east = -np.sin(lon0) * dx + np.cos(lon0) * dy
    north = (-np.sin(lat0) * np.cos(lon0) * dx - np.sin(lat0) * np.sin(lon0) * dy
             + np.cos(lat0) * dz)
    return north, east


def local_to_latlon(north, east, ref_lat_deg: float, ref_lon_deg: float):
    """(x0 north, y0 east) [m], shape (N,), on the tangent plane -> lat, lon [deg] at height 0.

    The tangent-plane point is projected along the ellipsoid normal onto the surface, so
    `latlon_to_local` returns (north, east) up to the tiny plane-vs-surface drop (< 1 mm
    within 2 km of the reference).
    """
    north, east = np.asarray(north, float), np.asarray(east, float)
    lat0, lon0 = np.radians(ref_lat_deg), np.radians(ref_lon_deg)
    x_0, y_0, z_0 = _ecef(np.array(lat0), np.array(lon0))
    x = x_0 - np.sin(lon0) * east - np.sin(lat0) * np.cos(lon0) * north
    y = y_0 + np.cos(lon0) * east - np.sin(lat0) * np.sin(lon0) * north
    z = z_0 + np.cos(lat0) * north
    lon = np.arctan2(y, x)
    p = np.hypot(x, y)
    lat = np.arctan2(z, p * (1.0 - E2))
    for _ in range(5):
        n = A / np.sqrt(1.0 - E2 * np.sin(lat) ** 2)
        h = p / np.cos(lat) - n
        lat = np.arctan2(z, p * (1.0 - E2 * n / (n + h)))
    return np.degrees(lat), np.degrees(lon)
