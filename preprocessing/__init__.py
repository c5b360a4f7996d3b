"""Raw 10 Hz ship logs to clean 1 Hz training data (numpy, pandas, scipy, filterpy).

This package never imports `sysid` or torch; it takes a `SensorLayout` value.
"""
from preprocessing.sensors import SensorLayout

__all__ = ["SensorLayout"]
