"""Robot motion for the simulator, defined by unicycle controls.

A path is a curvature profile kappa(s) over arc length. The robot drives it with a smooth speed profile,
so at the sensor rate the controls are v(t) and omega(t) = kappa(s(t)) v(t). Ground truth is the exact
integral of those piecewise-constant controls (arcs), so noise-free wheel odometry reproduces it exactly.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np

from odometry.shared.poses import arc_step, integrate_arcs, wrap_angle


class TrajectoryKind(str, enum.Enum):
    LOOP = "loop"              # closed rounded rectangle, back to the start
    FIGURE8 = "figure8"        # closed figure-eight
    LAWNMOWER = "lawnmower"    # back-and-forth rows, then a pass across them (revisits)
    RANDOM = "random"          # smooth random walk within a bounded area
    LANES = "lanes"            # survey lanes flown in alternating directions, joined by turns in place


@dataclass(frozen=True)
class Controls:
    """Unicycle controls at a fixed rate and the exact poses they produce."""

    t: np.ndarray        # (N + 1,) sample times
    v: np.ndarray        # (N,) forward speed over [t_i, t_i+1)
    omega: np.ndarray    # (N,) yaw rate over [t_i, t_i+1)
    poses: np.ndarray    # (N + 1, 3) poses at t

    def pose_at(self, times: np.ndarray) -> np.ndarray:
        """Exact poses at arbitrary times within the run (arc integration from the previous sample)."""
        times = np.asarray(times, dtype=float)
        i = np.clip(np.searchsorted(self.t, times, side="right") - 1, 0, len(self.v) - 1)
        dt = times - self.t[i]
        return arc_step(self.poses[i], self.v[i], self.omega[i], dt)


# ---------------------------------------------------------------------------------------------------- paths

def _segments_loop(length: float, turn_radius: float, aspect: float = 1.6) -> list[tuple[float, float]]:
    """Rounded rectangle: (segment length, curvature) pairs, total heading change 2*pi (closes exactly)."""
    r = min(turn_radius, length / (2 * math.pi + 4) * 0.9)
    straight = max(length - 2 * math.pi * r, 0.0)
    a = straight / 2 * aspect / (1 + aspect)
    b = straight / 2 - a
    arc = math.pi / 2 * r
    return [(a, 0.0), (arc, 1 / r), (b, 0.0), (arc, 1 / r), (a, 0.0), (arc, 1 / r), (b, 0.0), (arc, 1 / r)]


def _segments_figure8(length: float, turn_radius: float) -> list[tuple[float, float]]:
    """Two 270-degree arcs in opposite directions joined by straights through the crossing point.

    Starting at the crossing, the path returns to it exactly when every straight leg equals the radius r,
    so r = length / (4 + 3 pi) (the turn_radius argument does not apply)."""
    r = length / (4 + 3 * math.pi)
    arc = 1.5 * math.pi * r
    return [(r, 0.0), (arc, 1 / r), (2 * r, 0.0), (arc, -1 / r), (r, 0.0)]


def _segments_lawnmower(length: float, turn_radius: float) -> list[tuple[float, float]]:
    """Rows joined by half-turns, then a pass back across all rows (revisiting them)."""
    r = turn_radius
    n_rows = 4
    row = max((length * 0.75 - (n_rows - 1) * math.pi * r) / n_rows, 1.0)
    segs: list[tuple[float, float]] = []
    for k in range(n_rows):
        segs.append((row, 0.0))
        if k < n_rows - 1:
            segs.append((math.pi * r, (1 if k % 2 == 0 else -1) / r))
    # turn 90 degrees towards the first row and drive back across the rows
    width = (n_rows - 1) * 2 * r
    turn = 1 if n_rows % 2 == 0 else -1
    segs += [(math.pi / 2 * r, turn / r), (max(width + row * 0.0, 0.5), 0.0)]
    done = sum(s for s, _ in segs)
    if length > done:
        segs.append((math.pi / 2 * r, turn / r))
        segs.append((length - done, 0.0))
    return segs


def _curvature_random(length: float, ds: float, rng: np.random.Generator, radius: float, max_kappa: float
                      ) -> np.ndarray:
    """Smoothly varying curvature that keeps the path within `radius` of the start (pure pursuit of random goals)."""
    n = int(math.ceil(length / ds))
    kappa = np.zeros(n)
    pose = np.zeros(3)
    goal = rng.uniform(-radius, radius, 2)
    k_prev = 0.0
    for i in range(n):
        d = goal - pose[:2]
        if np.hypot(*d) < 0.5:
            goal = rng.uniform(-radius, radius, 2)
            d = goal - pose[:2]
        err = wrap_angle(math.atan2(d[1], d[0]) - pose[2])
        k = float(np.clip(1.5 * err, -max_kappa, max_kappa))
        k = k_prev + float(np.clip(k - k_prev, -0.05, 0.05))
        kappa[i] = k
        k_prev = k
        pose = arc_step(pose, np.asarray(ds), np.asarray(k * ds), np.asarray(1.0))
    return kappa


def curvature_profile(kind: TrajectoryKind | str, length: float, ds: float, rng: np.random.Generator,
                      turn_radius: float = 1.0, smoothing: float = 0.3) -> np.ndarray:
    """kappa at arc-length steps of `ds` metres over `length` metres. Piecewise profiles are smoothed with a
    moving average of `smoothing` metres, which keeps each turn's total heading change (and so closure)."""
    kind = TrajectoryKind(kind)
    if kind == TrajectoryKind.RANDOM:
        return _curvature_random(length, ds, rng, radius=max(2.0, math.sqrt(length) * 0.8), max_kappa=1 / turn_radius)
    segs = {TrajectoryKind.LOOP: _segments_loop, TrajectoryKind.FIGURE8: _segments_figure8,
            TrajectoryKind.LAWNMOWER: _segments_lawnmower}[kind](length, turn_radius)
    total = sum(s for s, _ in segs)
    n = int(math.ceil(total / ds))
    s_mid = (np.arange(n) + 0.5) * ds
    bounds = np.cumsum([0.0] + [s for s, _ in segs])
    idx = np.clip(np.searchsorted(bounds, s_mid, side="right") - 1, 0, len(segs) - 1)
    kappa = np.array([k for _, k in segs])[idx]
    w = max(1, int(round(smoothing / ds)))
    if w > 1:
        kernel = np.ones(w) / w
        kappa = np.convolve(np.concatenate([np.full(w, kappa[0]), kappa, np.full(w, kappa[-1])]) if
                            kind == TrajectoryKind.LAWNMOWER else np.concatenate([kappa[-w:], kappa, kappa[:w]]),
                            kernel, mode="same")[w:-w]
    return kappa


def drive(kappa: np.ndarray, ds: float, speed: float, rate: float, accel: float = 0.5,
          rng: np.random.Generator | None = None, speed_variation: float = 0.1, start_pause: float = 0.5,
          end_pause: float = 0.5) -> Controls:
    """Drive the curvature profile at ~`speed` m/s with acceleration ramps; controls sampled at `rate` Hz.

    The speed wanders slowly by +-speed_variation (relative) and is limited in turns so that |omega| stays modest.
    The robot rests `start_pause` / `end_pause` seconds at the ends.
    """
    total = len(kappa) * ds
    dt = 1.0 / rate
    n_max = int((total / max(speed * 0.3, 1e-3) + start_pause + end_pause) * rate) + 10
    v_out, w_out = [], []
    s, v = 0.0, 0.0
    phase = 0.0 if rng is None else float(rng.uniform(0, 2 * math.pi))
    period = 7.0
    t = 0.0
    for _ in range(int(start_pause * rate)):
        v_out.append(0.0)
        w_out.append(0.0)
        t += dt
    while s < total and len(v_out) < n_max:
        i = min(int(s / ds), len(kappa) - 1)
        k = kappa[i]
        target = speed * (1 + speed_variation * math.sin(2 * math.pi * t / period + phase))
        target = min(target, 1.2 / max(abs(k), 1e-9))           # |omega| <= 1.2 rad/s
        remaining = total - s
        target = min(target, math.sqrt(2 * accel * max(remaining, 0.0)) + 1e-3)  # brake to stop at the end
        v = min(target, v + accel * dt) if target > v else max(target, v - accel * dt)
        step = min(v * dt, remaining)
        v_eff = step / dt
        v_out.append(v_eff)
        w_out.append(k * v_eff)
        s += step
        t += dt
    for _ in range(int(end_pause * rate)):
        v_out.append(0.0)
        w_out.append(0.0)
    v_arr, w_arr = np.asarray(v_out), np.asarray(w_out)
    times = np.arange(len(v_arr) + 1) * dt
    return Controls(t=times, v=v_arr, omega=w_arr, poses=integrate_arcs(v_arr, w_arr, dt))


def lanes_controls(length: float, spacing: float, n_lanes: int, speed: float, rate: float, turn_rate: float = 1.2,
                   pause: float = 0.5) -> Controls:
    """Parallel lanes flown in alternating directions (a survey pattern): along a lane at `speed`, then a 90 degree
    turn in place, `spacing` metres across, another 90 degree turn in place (180 degrees in all), the next lane.
    Lane length: what is left of `length` after the crossings, shared by the lanes. Controls at `rate` Hz."""
    if n_lanes < 1 or spacing <= 0 or speed <= 0:
        raise ValueError("lanes need n_lanes >= 1, spacing > 0 and speed > 0")
    lane = (length - (n_lanes - 1) * spacing) / n_lanes
    if lane <= 0:
        raise ValueError(f"path length {length} m is too short for {n_lanes} lanes {spacing} m apart")
    dt = 1.0 / rate
    steps: list[tuple[float, float, float]] = [(0.0, 0.0, pause)]   # (v, omega, duration)
    for k in range(n_lanes):
        steps.append((speed, 0.0, lane / speed))
        if k < n_lanes - 1:
            turn = 1.0 if k % 2 == 0 else -1.0   # left, then right: lanes alternate in direction
            steps += [(0.0, turn * turn_rate, math.pi / 2 / turn_rate), (speed, 0.0, spacing / speed),
                      (0.0, turn * turn_rate, math.pi / 2 / turn_rate)]
    steps.append((0.0, 0.0, pause))
    v_out, w_out = [], []
    carry = 0.0
    for v, w, dur in steps:
        # whole control intervals; the remainder carries over so that distances and angles stay exact
        n = int(math.floor((dur + carry) / dt + 1e-9))
        frac = (dur + carry) / dt - n
        v_out += [v] * n
        w_out += [w] * n
        carry = frac * dt
        if carry > 1e-12 and len(v_out) > 0:
            # the remainder as one shortened-rate interval: same distance/angle over a full dt
            v_out.append(v * carry / dt)
            w_out.append(w * carry / dt)
            carry = 0.0
    v_arr, w_arr = np.asarray(v_out), np.asarray(w_out)
    times = np.arange(len(v_arr) + 1) * dt
    return Controls(t=times, v=v_arr, omega=w_arr, poses=integrate_arcs(v_arr, w_arr, dt))
