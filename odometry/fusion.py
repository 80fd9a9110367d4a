"""Wheel odometry + gyro fusion: an extended Kalman filter (filterpy) over the planar pose and the gyro bias.

State x = [x, y, theta, b, s, k]: robot pose in the frame of the first query time, the gyro's additive yaw-rate
bias b (rad/s), the relative scale error s of the wheel yaw rate (wheel-base error: a few per cent on real
robots; left uncorrected it would leak into the bias estimate in every turn), and the relative scale error k of
the wheel speed (wheel radius). k is not observable from these sensors: it stays at its prior mean, but its
prior makes the position covariance grow with distance the way a scale error does (linearly, not as a random
walk), so long-range covariances stay honest. Sensors, each at its own times:

- wheel speed v = (1 + k) v_true + n_v (m/s, forward): the translational input of the unicycle model;
- wheel yaw rate omega_w = (1 + s) omega + n_w (differential encoders; slip and wheel-base error);
- gyro yaw rate omega_g = omega + b + n_g.

The true yaw rate omega is a nuisance quantity eliminated per interval. With the corrected wheel rate
w' = omega_w / (1 + s) and interval variances q_w, q_g, the two sufficient statistics are

    (1 - alpha) w' + alpha (omega_g - b)   alpha = q_w / (q_w + q_g), variance q_w q_g / (q_w + q_g) -> theta (predict)
    0 = omega_w - (1 + s)(omega_g - b) + noise   variance q_w + (1 + s)^2 q_g                  -> b, s (update)

and their noises are uncorrelated, so each piece of information is used once. With one rate source only
(wheel-only, or gyro + wheel speed) alpha is 0 or 1 and there is no update: b and s keep their priors and the
heading uncertainty grows accordingly, which is honest.

Time: the wheel, gyro and query timestamps are merged and the unicycle is integrated exactly over each interval
(constant-curvature arc). A sample holds until the next one (the sequence format's convention, `Interpolation.HOLD`)
or rates are interpolated linearly (`Interpolation.LINEAR`). Noise-free inputs reproduce the exact integral.

Noise parameters are per-sample standard deviations (what a data sheet or a log gives); they are turned into
densities with each stream's median sampling period, so the result does not depend on how the timeline is cut.
Distance-proportional slip terms model wheel slip (variance grows with distance travelled).

`FusedTrajectory.relative(i, j)` returns the motion i -> j and its covariance including the cross-covariance
between the two poses (tracked through the filter's error transition matrices), so short-range relative motions
are tight even when the absolute poses have drifted: that is what seed 001's loop-model training uses.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

import numpy as np

from odometry.errors import OdometryError
from odometry.shared.config import Config, setting
from odometry.shared.pose_covariance import between_jacobians
from odometry.shared.poses import arc_chord, between, wrap_angle

__all__ = ["FusionConfig", "FusedTrajectory", "Interpolation", "fuse_wheel_gyro"]


class Interpolation(str, Enum):
    """How a sampled rate is read between samples."""

    HOLD = "hold"      # each sample holds until the next (odometry.csv / imu.csv convention)
    LINEAR = "linear"  # linear between samples


@dataclass(frozen=True)
class FusionConfig(Config):
    """Noise model of the wheel/gyro fusion. Per-sample standard deviations unless stated otherwise.

    Attributes:
        wheel_v_sigma: white noise of one wheel-speed sample (m/s).
        wheel_omega_sigma: white noise of one wheel yaw-rate sample (rad/s).
        gyro_sigma: white noise of one gyro sample (rad/s).
        slip_forward: forward distance error from wheel scale and slip, m per sqrt(m) travelled.
        slip_lateral: sideways slip, m per sqrt(m) travelled (a unicycle cannot move sideways; real robots do).
        slip_heading: wheel yaw-rate error from wheel-base error and slip, rad per sqrt(m) travelled.
        gyro_bias_sigma0: prior standard deviation of the gyro bias (rad/s); the prior mean is `gyro_bias0`.
        gyro_bias0: prior mean of the gyro bias (rad/s), e.g. from a stationary calibration.
        gyro_bias_walk: bias random walk (rad/s per sqrt(s)).
        wheel_scale_sigma0: prior standard deviation of the wheel yaw-rate scale error s (prior mean 0);
            0 disables its estimation.
        wheel_scale_walk: random walk of s per sqrt(m) travelled (floor changes alter the effective wheel base).
        speed_scale_sigma0: prior standard deviation of the wheel speed scale error k (wheel radius, tyre wear).
        interpolation: how rates are read between samples (HOLD: the sequence format's convention).
        bias_gate: chi-square (1 dof) gate on the bias innovation; larger disagreements between gyro and wheel
            yaw rates are slip, not bias, and are not used to update the bias. 0 disables the gate.
        max_gap: a stream with a sample gap longer than this (s) is treated as missing over the whole gap.
        gap_speed_sigma: speed uncertainty (m/s) over intervals without wheel data (speed is interpolated).
        gap_rate_sigma: yaw-rate uncertainty (rad/s) over intervals with no rate sensor at all.
    """

    LABEL = "fusion"
    PRESETS = {
        # a differential-drive indoor robot with wheel encoders and a consumer MEMS gyro
        "default": {},
        # good encoders on a hard floor and a stable (e.g. fibre-optic or calibrated MEMS) gyro
        "precise": {"wheel_v_sigma": 0.005, "wheel_omega_sigma": 0.01, "gyro_sigma": 0.001, "slip_forward": 0.003,
                    "slip_lateral": 0.001, "slip_heading": 0.003, "gyro_bias_sigma0": 0.005, "gyro_bias_walk": 1e-5},
        # carpet, grass or wet floors: large wheel slip, trust the gyro for heading
        "slippery": {"wheel_v_sigma": 0.03, "wheel_omega_sigma": 0.08, "slip_forward": 0.03, "slip_lateral": 0.015,
                     "slip_heading": 0.05},
    }

    wheel_v_sigma: float = setting(0.02, range="[0, inf)", unit="m/s")
    wheel_omega_sigma: float = setting(0.03, range="[0, inf)", unit="rad/s")
    gyro_sigma: float = setting(0.005, range="[0, inf)", unit="rad/s")
    slip_forward: float = setting(0.01, range="[0, inf)", unit="m/sqrt(m)")
    slip_lateral: float = setting(0.005, range="[0, inf)", unit="m/sqrt(m)")
    slip_heading: float = setting(0.01, range="[0, inf)", unit="rad/sqrt(m)")
    gyro_bias_sigma0: float = setting(0.02, range="[0, inf)", unit="rad/s")
    gyro_bias0: float = setting(0.0, unit="rad/s")
    gyro_bias_walk: float = setting(2e-4, range="[0, inf)", unit="rad/s/sqrt(s)")
    wheel_scale_sigma0: float = setting(0.05, range="[0, inf)")
    wheel_scale_walk: float = setting(1e-3, range="[0, inf)", unit="1/sqrt(m)")
    speed_scale_sigma0: float = setting(0.02, range="[0, inf)")
    interpolation: Interpolation = Interpolation.HOLD
    bias_gate: float = setting(10.83, range="[0, inf)", doc="chi2(1) at 99.9 %")
    max_gap: float = setting(0.5, range="(0, inf)", unit="s")
    gap_speed_sigma: float = setting(0.5, range="[0, inf)", unit="m/s")
    gap_rate_sigma: float = setting(0.5, range="[0, inf)", unit="rad/s")


@dataclass
class FusedTrajectory:
    """Fused poses at the query times.

    Attributes:
        timestamps: (M,) the query times.
        poses: (M, 3) x, y, theta; the first pose is the origin.
        covariances: (M, 3, 3) marginal covariance of each pose.
        bias: (M,) estimated gyro bias (rad/s) at each query time (NaN without a gyro).
        bias_sigma: (M,) its standard deviation.
        transitions: (M, 6, 6) error transition of the full state [x, y, theta, b, s, k] from query i-1 to query
            i (identity for i = 0), used for the cross-covariances of `relative`.
        state_covariances: (M, 6, 6) full state covariance at each query time.
        wheel_scale: (M,) estimated wheel yaw-rate scale error s (NaN unless both rate sources are given).
    """

    timestamps: np.ndarray
    poses: np.ndarray
    covariances: np.ndarray
    bias: np.ndarray | None = None
    bias_sigma: np.ndarray | None = None
    transitions: np.ndarray | None = None
    state_covariances: np.ndarray | None = None
    wheel_scale: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.timestamps)

    def cross_covariance(self, i: int, j: int) -> np.ndarray:
        """Cov(error_j, error_i) of the full state, i <= j (Phi_{j<-i} P_i)."""
        if self.transitions is None or self.state_covariances is None:
            raise ValueError("this trajectory carries no transition matrices; relative covariances are unavailable")
        phi = np.eye(self.transitions.shape[1])
        for k in range(i + 1, j + 1):
            phi = self.transitions[k] @ phi
        return phi @ self.state_covariances[i]

    def relative(self, i: int, j: int) -> tuple[np.ndarray, np.ndarray]:
        """Motion from pose i to pose j (between(pose_i, pose_j), shape (3,)) and its 3x3 covariance.

        The covariance accounts for the correlation of the two poses, so it reflects only the odometry error
        accumulated between the two query times (plus the effect of the shared bias estimate).
        """
        n = len(self.timestamps)
        for name, k in (("i", i), ("j", j)):
            if not -n <= k < n:
                raise IndexError(f"{name}={k} out of range for a trajectory of {n} poses")
        i, j = i % n, j % n
        if i == j:
            return np.zeros(3), np.zeros((3, 3))
        a, b = min(i, j), max(i, j)
        d = between(self.poses[i], self.poses[j])
        ji, jj = between_jacobians(self.poses[i], self.poses[j])
        if self.transitions is None or self.state_covariances is None:
            # marginals only: an upper bound that ignores the positive correlation of the two poses
            cov = ji @ self.covariances[i] @ ji.T + jj @ self.covariances[j] @ jj.T
        else:
            c_ba = self.cross_covariance(a, b)[:3, :3]  # Cov(e_b, e_a)
            c_ji = c_ba if j > i else c_ba.T           # Cov(e_j, e_i)
            cross = jj @ c_ji @ ji.T
            cov = (ji @ self.state_covariances[i][:3, :3] @ ji.T + jj @ self.state_covariances[j][:3, :3] @ jj.T
                   + cross + cross.T)
        cov = 0.5 * (cov + cov.T)
        return d, cov


# ---------------------------------------------------------------------------------------------------- inputs

def _stream(name: str, t: np.ndarray | None, *values: tuple[str, np.ndarray | None]) -> tuple | None:
    if t is None:
        return None
    t = np.asarray(t, dtype=float).reshape(-1)
    out = [t]
    for vname, v in values:
        if v is None:
            out.append(None)
            continue
        v = np.asarray(v, dtype=float).reshape(-1)
        if len(v) != len(t):
            raise OdometryError(f"{vname}: {len(v)} values for {len(t)} {name} timestamps")
        bad = np.flatnonzero(~np.isfinite(v))
        if len(bad):
            raise OdometryError(f"{vname}: non-finite value at sample {bad[0]}")
        out.append(v)
    if len(t) == 0:
        raise OdometryError(f"{name} timestamps are empty")
    bad = np.flatnonzero(~np.isfinite(t))
    if len(bad):
        raise OdometryError(f"{name} timestamps: non-finite value at sample {bad[0]}")
    back = np.flatnonzero(np.diff(t) <= 0)
    if len(back):
        raise OdometryError(f"{name} timestamps must increase strictly: sample {back[0] + 1} "
                         f"(t={t[back[0] + 1]!r}) follows t={t[back[0]]!r}")
    return tuple(out)


def _period(t: np.ndarray) -> float:
    return float(np.median(np.diff(t))) if len(t) > 1 else 1.0


def _gap_span(t: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Length of the sample gap each time in `at` falls into (the distance to the end sample outside the span):
    values interpolated across a long gap are guesses over the whole gap, not only in its middle."""
    k = np.searchsorted(t, at, side="right")
    span = np.empty_like(at)
    inside = (k > 0) & (k < len(t))
    span[inside] = t[k[inside]] - t[k[inside] - 1]
    span[k == 0] = t[0] - at[k == 0]
    span[k == len(t)] = at[k == len(t)] - t[-1]
    return span


# ---------------------------------------------------------------------------------------------------- the filter

_DIM = 6  # x, y, theta, gyro bias, wheel-rate scale error, wheel-speed scale error


def _make_ekf(cfg: FusionConfig):
    from filterpy.kalman import ExtendedKalmanFilter  # filterpy pulls in scipy: keep the package import light

    class _PlanarEKF(ExtendedKalmanFilter):
        """Unicycle with an exact arc step; u = (v, omega_w, omega_g, alpha, dt)."""

        def predict_x(self, u=0):
            v, om_w, om_g, alpha, dt = u
            x = self.x
            w = (1.0 - alpha) * om_w / (1.0 + x[4, 0]) + alpha * (om_g - x[3, 0])
            chord, dth = arc_chord(v / (1.0 + x[5, 0]), w, dt)
            phi = x[2, 0] + 0.5 * dth
            x[0, 0] += chord * math.cos(phi)
            x[1, 0] += chord * math.sin(phi)
            x[2, 0] = wrap_angle(x[2, 0] + dth)

    ekf = _PlanarEKF(dim_x=_DIM, dim_z=1)
    ekf.x = np.array([[0.0], [0.0], [0.0], [cfg.gyro_bias0], [0.0], [0.0]])
    ekf.P = np.diag([0.0, 0.0, 0.0, cfg.gyro_bias_sigma0 ** 2, cfg.wheel_scale_sigma0 ** 2,
                     cfg.speed_scale_sigma0 ** 2])
    return ekf


def fuse_wheel_gyro(wheel_t: np.ndarray | None, v: np.ndarray | None, omega: np.ndarray | None,
                    gyro_t: np.ndarray | None, gyro_z: np.ndarray | None, query_t: np.ndarray,
                    config: FusionConfig | None = None) -> FusedTrajectory:
    """Fuse wheel odometry (speed v, yaw rate omega) with a gyro (yaw rate gyro_z) into poses at `query_t`.

    Args:
        wheel_t, v, omega: wheel odometry samples (N,), forward speed m/s and yaw rate rad/s. `omega` may be None
            (gyro + wheel speed). The wheel speed is required: nothing else observes translation.
        gyro_t, gyro_z: gyro samples (G,) in rad/s, or both None (wheel-only dead reckoning).
        query_t: (M,) non-decreasing times at which poses are wanted (e.g. camera frames). The first pose is the
            origin; rates outside a stream's time span are held at its end values (and inflated after `max_gap`).
        config: noise model; FusionConfig() if None.

    Returns:
        FusedTrajectory with poses (M, 3), marginal covariances (M, 3, 3), the bias estimate and what
        `relative(i, j)` needs for correlated relative covariances.

    Raises:
        ValueError: mismatched lengths, non-finite values, non-increasing timestamps, or no yaw-rate source.
    """
    cfg = config or FusionConfig()
    if wheel_t is None or v is None:
        raise OdometryError("wheel odometry speed is required (wheel_t and v): no other input observes translation")
    wheel = _stream("wheel", wheel_t, ("wheel v", v), ("wheel omega", omega))
    gyro = None
    if gyro_t is not None or gyro_z is not None:
        if gyro_t is None or gyro_z is None:
            raise OdometryError("gyro_t and gyro_z must be given together")
        gyro = _stream("gyro", gyro_t, ("gyro_z", gyro_z))
    wt, wv, ww = wheel
    if ww is None and gyro is None:
        raise OdometryError("no yaw-rate source: give the wheel omega, the gyro, or both")
    q = np.asarray(query_t, dtype=float).reshape(-1)
    if len(q) == 0:
        raise OdometryError("query_t is empty")
    if not np.all(np.isfinite(q)):
        raise OdometryError(f"query_t: non-finite value at index {int(np.flatnonzero(~np.isfinite(q))[0])}")
    if np.any(np.diff(q) < 0):
        k = int(np.flatnonzero(np.diff(q) < 0)[0])
        raise OdometryError(f"query_t must be non-decreasing: index {k + 1} (t={q[k + 1]!r}) follows t={q[k]!r}")

    # merged timeline over the query span; sensor times a rounding error away from a query time would only make
    # degenerate intervals, so they are dropped
    sensor = [wt[(wt > q[0]) & (wt < q[-1])]]
    if gyro is not None:
        sensor.append(gyro[0][(gyro[0] > q[0]) & (gyro[0] < q[-1])])
    st = np.concatenate(sensor)
    pos = np.searchsorted(q, st)
    gap = np.minimum(np.abs(st - q[np.maximum(pos - 1, 0)]), np.abs(q[np.minimum(pos, len(q) - 1)] - st))
    times = np.unique(np.concatenate([q, st[gap > 1e-9]]))
    mids = 0.5 * (times[:-1] + times[1:])
    dts = np.diff(times)

    # per-interval rates and the variances of their interval averages: white noise of a sample sigma at period T
    # integrates to sigma^2 T dt, slip to k^2 |v| dt; divided by dt^2 for a rate
    def read(t: np.ndarray, x: np.ndarray) -> np.ndarray:
        if cfg.interpolation == Interpolation.LINEAR:
            return np.interp(mids, t, x)
        return x[np.clip(np.searchsorted(t, mids, side="right") - 1, 0, len(t) - 1)]

    period_w = _period(wt)
    v_mid = read(wt, wv)
    w_stale = _gap_span(wt, mids) > cfg.max_gap
    dist_rate = np.abs(v_mid)  # m/s, for the slip terms
    var_v = (cfg.wheel_v_sigma ** 2 * period_w + cfg.slip_forward ** 2 * dist_rate) / dts
    # a held speed is wrong in a correlated way: a density with correlation time max_gap keeps it cut-independent
    var_v = np.where(w_stale, var_v + cfg.gap_speed_sigma ** 2 * cfg.max_gap / dts, var_v)
    lat_var = cfg.slip_lateral ** 2 * dist_rate * dts  # sideways position variance of the step (m^2)
    big = np.inf
    if ww is not None:
        om_w = read(wt, ww)
        var_w = (cfg.wheel_omega_sigma ** 2 * period_w + cfg.slip_heading ** 2 * dist_rate) / dts
        var_w = np.where(w_stale, big, var_w)
    else:
        om_w = np.zeros_like(mids)
        var_w = np.full_like(mids, big)
    if gyro is not None:
        gt, gz = gyro
        om_g = read(gt, gz)
        var_g = cfg.gyro_sigma ** 2 * _period(gt) / dts
        var_g = np.where(_gap_span(gt, mids) > cfg.max_gap, big, var_g)
    else:
        om_g = np.zeros_like(mids)
        var_g = np.full_like(mids, big)

    has_w = np.isfinite(var_w)
    has_g = np.isfinite(var_g)

    ekf = _make_ekf(cfg)
    gate = cfg.bias_gate
    walk_b2 = cfg.gyro_bias_walk ** 2
    walk_s2 = cfg.wheel_scale_walk ** 2
    eye = np.eye(_DIM)
    qidx = np.searchsorted(times, q)  # the timeline index of each query
    m = len(q)
    poses = np.zeros((m, 3))
    pcov = np.zeros((m, _DIM, _DIM))
    trans = np.tile(eye, (m, 1, 1))
    extra = np.zeros((m, 2))  # b, s
    phi = eye.copy()
    qi = 0
    pcov[0], extra[0] = ekf.P, ekf.x[3:5, 0]
    while qi + 1 < m and qidx[qi + 1] == 0:  # repeated first query time
        qi += 1
        pcov[qi], extra[qi] = ekf.P, ekf.x[3:5, 0]
    F = np.eye(_DIM)
    Q = np.zeros((_DIM, _DIM))
    H = np.zeros((1, _DIM))
    z0 = np.zeros((1, 1))
    for k in range(len(dts)):
        dt = dts[k]
        th, b, sc, kv = ekf.x[2, 0], ekf.x[3, 0], ekf.x[4, 0], ekf.x[5, 0]
        vk = v_mid[k] / (1.0 + kv)
        inv1s = 1.0 / (1.0 + sc)
        wc = om_w[k] * inv1s  # wheel rate corrected for the scale error
        if has_w[k] and has_g[k]:
            qw = var_w[k] * inv1s * inv1s
            al = qw / (qw + var_g[k])
            var_c = qw * var_g[k] / (qw + var_g[k])
        elif has_g[k]:
            al, var_c = 1.0, var_g[k]
        elif has_w[k]:
            al, var_c = 0.0, var_w[k] * inv1s * inv1s
        else:  # no rate sensor: hold the interpolated wheel rate, with a large uncertainty
            al, var_c = 0.0, cfg.gap_rate_sigma ** 2 * cfg.max_gap / dt
        w = (1.0 - al) * wc + al * (om_g[k] - b)
        chord, dth = arc_chord(vk, w, dt)
        phi_h = th + 0.5 * dth
        cph, sph = math.cos(phi_h), math.sin(phi_h)
        # Jacobian: heading swings the chord; b and s turn the heading (and half of the chord)
        dw_db, dw_ds = -al, -(1.0 - al) * wc * inv1s
        perp_x, perp_y = -0.5 * dt * chord * sph, 0.5 * dt * chord * cph
        F[0, 2], F[1, 2] = -chord * sph, chord * cph
        F[0, 3], F[1, 3], F[2, 3] = perp_x * dw_db, perp_y * dw_db, dt * dw_db
        F[0, 4], F[1, 4], F[2, 4] = perp_x * dw_ds, perp_y * dw_ds, dt * dw_ds
        F[0, 5], F[1, 5] = -chord * cph / (1.0 + kv), -chord * sph / (1.0 + kv)
        # noise: speed error along the chord, rate error turns heading and chord, lateral slip across it
        g_v = np.array([dt * cph, dt * sph, 0.0])
        g_w = np.array([perp_x, perp_y, dt])
        g_l = np.array([-sph, cph, 0.0])
        Q[:3, :3] = var_v[k] * np.outer(g_v, g_v) + var_c * np.outer(g_w, g_w) + lat_var[k] * np.outer(g_l, g_l)
        Q[3, 3] = walk_b2 * dt
        Q[4, 4] = walk_s2 * dist_rate[k] * dt
        ekf.F, ekf.Q = F, Q
        ekf.predict(u=(v_mid[k], om_w[k], om_g[k], al, dt))
        phi = F @ phi
        if has_w[k] and has_g[k]:
            # implicit measurement 0 = omega_w - (1 + s)(omega_g - b) + noise. The gyro rate is the regressor of s
            # (not the much noisier wheel rate): a noisy regressor correlates with the residual and biases s.
            b, sc = ekf.x[3, 0], ekf.x[4, 0]
            g_rate = om_g[k] - b
            resid = om_w[k] - (1.0 + sc) * g_rate
            H[0, 3], H[0, 4] = 1.0 + sc, -g_rate
            r = var_w[k] + (1.0 + sc) ** 2 * var_g[k]
            s_inn = float((H @ ekf.P @ H.T)[0, 0]) + r
            if gate <= 0 or resid * resid <= gate * s_inn:
                ekf.update(z0, lambda x, H=H: H, lambda x, c=resid: np.array([[c]]), R=np.array([[r]]))
                phi = (eye - ekf.K @ H) @ phi
        while qi + 1 < m and qidx[qi + 1] == k + 1:
            qi += 1
            poses[qi] = ekf.x[:3, 0]
            pcov[qi] = ekf.P
            trans[qi] = phi
            extra[qi] = ekf.x[3:5, 0]
            phi = eye.copy()
    pcov = 0.5 * (pcov + np.swapaxes(pcov, 1, 2))
    nan = np.full(m, np.nan)
    has_gyro = gyro is not None
    return FusedTrajectory(
        timestamps=q, poses=poses, covariances=pcov[:, :3, :3].copy(),
        bias=extra[:, 0] if has_gyro else nan,
        bias_sigma=np.sqrt(np.maximum(pcov[:, 3, 3], 0.0)) if has_gyro else nan,
        transitions=trans, state_covariances=pcov,
        wheel_scale=extra[:, 1] if has_gyro and ww is not None else nan.copy())
