"""Wheel odometry and gyro measurements from the true unicycle controls, with realistic errors.

Convention (also for recorded data): a row of odometry.csv / imu.csv holds the velocity at that instant; the
simulator's controls are constant until the next row, so integrating each row over the interval up to the next
one reproduces the ground truth exactly when noise is off.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from odometry.shared.config import Config, setting


@dataclass(frozen=True)
class SensorNoise(Config):
    PRESETS = {"none": {"v_noise": 0.0, "omega_noise": 0.0, "v_scale_error": 0.0, "omega_scale_error": 0.0,
                        "slip_rate": 0.0, "slip_duration": 0.0, "slip_magnitude": 0.0, "gyro_noise": 0.0,
                        "gyro_bias": 0.0, "gyro_bias_walk": 0.0}}

    v_noise: float = setting(0.01, range="[0, inf)", unit="m/s", doc="white")
    omega_noise: float = setting(0.02, range="[0, inf)", unit="rad/s", doc="wheel yaw-rate white noise")
    v_scale_error: float = setting(0.02, range="[0, inf)", doc="relative: wheel radius error")
    omega_scale_error: float = setting(0.04, range="[0, inf)", doc="relative: track-width error")
    slip_rate: float = setting(0.05, range="[0, inf)", unit="1/s", doc="slip episodes per second")
    slip_duration: float = setting(0.6, range="[0, inf)", unit="s")
    slip_magnitude: float = setting(0.15, range="[0, inf)", doc="relative over-reading of v during a slip")
    gyro_noise: float = setting(0.004, range="[0, inf)", unit="rad/s", doc="white")
    gyro_bias: float = setting(0.004, unit="rad/s", doc="initial bias")
    gyro_bias_walk: float = setting(2e-4, range="[0, inf)", unit="rad/s/sqrt(s)")

    def scaled(self, k: float) -> "SensorNoise":
        return self.replace(**{f: getattr(self, f) * k for f in self.__dataclass_fields__})


def wheel_measurements(t: np.ndarray, v: np.ndarray, omega: np.ndarray, noise: SensorNoise,
                       rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(timestamps, v, omega) of wheel odometry, one row per control interval."""
    n = len(v)
    ts = t[:n]
    dt = float(t[1] - t[0]) if len(t) > 1 else 0.01
    slip = np.zeros(n)
    if noise.slip_rate > 0 and noise.slip_magnitude > 0:
        starts = np.nonzero(rng.random(n) < noise.slip_rate * dt)[0]
        length = max(1, int(noise.slip_duration / dt))
        for s in starts:
            slip[s:s + length] = noise.slip_magnitude * rng.uniform(0.5, 1.0)
    moving = np.abs(v) > 1e-9  # encoders read zero when the wheels stand still
    v_m = v * (1 + noise.v_scale_error) * (1 + slip) + moving * rng.normal(0, noise.v_noise, n)
    w_m = omega * (1 + noise.omega_scale_error) + moving * rng.normal(0, noise.omega_noise, n)
    return ts.copy(), v_m, w_m


def gyro_measurements(t: np.ndarray, omega: np.ndarray, noise: SensorNoise, rng: np.random.Generator
                      ) -> tuple[np.ndarray, np.ndarray]:
    """(timestamps, gyro_z): true yaw rate + slowly wandering bias + white noise."""
    n = len(omega)
    dt = float(t[1] - t[0]) if len(t) > 1 else 0.01
    bias = noise.gyro_bias + np.cumsum(rng.normal(0, noise.gyro_bias_walk * np.sqrt(dt), n))
    return t[:n].copy(), omega + bias + rng.normal(0, noise.gyro_noise, n)
