"""Predict where and when a rolling ball crosses the catch line (paper §6, the prediction subsystem).

A rolling ball moves on a straight line (every force on it acts along its velocity) and decelerates
as dv/dt = -(α + β v²) (rolling resistance + air drag; the simulated world uses the same law). The
line is fitted by least squares y = a + b·x, the along-track motion by Gauss–Newton on (s₀, v₀)
with the closed-form solution

    v(τ) = √(α/β) · tan(φ₀ - cτ),   s(τ) = s₀ + (1/β) · ln(cos(φ₀ - cτ) / cos φ₀),
    φ₀ = atan(v₀ √(β/α)),   c = √(αβ),

which also gives the time of arrival at the catch line in closed form. Uncertainties are propagated
from the least-squares covariances.

Pure: no I/O, no clocks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Prediction", "RollingModel", "RollingPredictor"]


@dataclass(frozen=True, slots=True)
class RollingModel:
    """Deceleration model of a rolling ball, dv/dt = -(α + β v²).

    Attributes:
        alpha: constant part (rolling resistance), m/s², >= 0.
        beta: quadratic part (air drag), 1/m, >= 0.
    """

    alpha: float
    beta: float

    def distance(self, v0: float | np.ndarray, tau: float | np.ndarray) -> np.ndarray:
        """Distance (m) travelled in time τ (s) from speed v0 (m/s); the ball stops at v = 0."""
        a, b = self.alpha, self.beta
        v0 = np.asarray(v0, dtype=float)
        tau = np.asarray(tau, dtype=float)
        out: np.ndarray
        if a <= 0.0 and b <= 0.0:
            out = v0 * tau
        elif b <= 0.0:
            tt = np.minimum(tau, v0 / a)
            out = v0 * tt - 0.5 * a * tt**2
        elif a <= 0.0:
            out = np.log1p(b * v0 * tau) / b
        else:
            c = math.sqrt(a * b)
            phi0 = np.arctan(v0 * math.sqrt(b / a))
            tt = np.minimum(tau, phi0 / c)
            out = np.log(np.cos(phi0 - c * tt) / np.cos(phi0)) / b
        return out

    def speed(self, v0: float, tau: float) -> float:
        """Speed (m/s) after time τ (s) from speed v0 (m/s), never below 0."""
        a, b = self.alpha, self.beta
        if a <= 0.0 and b <= 0.0:
            return v0
        if b <= 0.0:
            return max(0.0, v0 - a * tau)
        if a <= 0.0:
            return v0 / (1.0 + b * v0 * tau)
        c = math.sqrt(a * b)
        phi0 = math.atan(v0 * math.sqrt(b / a))
        return max(0.0, math.sqrt(a / b) * math.tan(phi0 - c * tau))

    def time_to_travel(self, v0: float, ds: float) -> float | None:
        """Time (s) to travel ds >= 0 metres from speed v0, or None if the ball stops first."""
        a, b = self.alpha, self.beta
        if ds <= 0.0:
            return 0.0
        if v0 <= 0.0:
            return None
        if a <= 0.0 and b <= 0.0:
            return ds / v0
        if b <= 0.0:
            disc = v0 * v0 - 2.0 * a * ds
            return None if disc < 0 else (v0 - math.sqrt(disc)) / a
        if a <= 0.0:
            return math.expm1(b * ds) / (b * v0)
        c = math.sqrt(a * b)
        phi0 = math.atan(v0 * math.sqrt(b / a))
        arg = math.cos(phi0) * math.exp(b * ds)
        if arg > 1.0:
            return None
        return (phi0 - math.acos(arg)) / c


@dataclass(frozen=True, slots=True)
class Prediction:
    """Predicted crossing of the catch line x = catch_x (table frame).

    Attributes:
        x: the catch line's x, m.
        y: predicted lateral crossing point, m.
        t: predicted time of the crossing, s (same clock as the observations).
        vx, vy: predicted velocity at the crossing, m/s.
        sigma_y: 1-σ uncertainty of y, m.
        sigma_t: 1-σ uncertainty of t, s.
        t_obs: timestamp of the last observation used, s.
        n: observations used.
    """

    x: float
    y: float
    t: float
    vx: float
    vy: float
    sigma_y: float
    sigma_t: float
    t_obs: float
    n: int


class RollingPredictor:
    """Iterative estimate of a rolling ball's trajectory and of its catch-line crossing.

    Feed it timestamped table positions of one throw with :meth:`add`; :meth:`predict` fits the
    straight path and the decelerating along-track motion to all of them and returns the predicted
    crossing of x = ``catch_x``. Call :meth:`reset` between throws.

    Args:
        model: deceleration model (α, β) of the rolling ball.
        catch_x: x of the catch line, m (the table's near edge).
        min_points: observations needed before a prediction is made.
        position_sigma: assumed 1-σ noise of an observed position, m (floor of the uncertainty).
        max_points: only the last ``max_points`` observations are used.
    """

    def __init__(
        self,
        model: RollingModel,
        *,
        catch_x: float = 0.0,
        min_points: int = 4,
        position_sigma: float = 0.001,
        max_points: int = 400,
    ) -> None:
        if min_points < 3:
            raise ValueError("min_points must be >= 3")
        self.model = model
        self.catch_x = catch_x
        self.min_points = min_points
        self.position_sigma = position_sigma
        self.max_points = max_points
        self._obs: list[tuple[float, float, float]] = []

    def reset(self) -> None:
        """Forget all observations (a new throw)."""
        self._obs.clear()

    @property
    def count(self) -> int:
        """Observations held."""
        return len(self._obs)

    def add(self, t: float, x: float, y: float) -> None:
        """Add an observed ball position (x, y) m at time t s; ignores points past the catch line."""
        if x >= self.catch_x:
            return
        if self._obs and t <= self._obs[-1][0]:
            return
        self._obs.append((float(t), float(x), float(y)))
        if len(self._obs) > self.max_points:
            del self._obs[0]

    def predict(self) -> Prediction | None:
        """Predict the crossing from the observations held.

        Returns:
            The prediction, or None with too few observations, a ball not moving towards the catch
            line, or a ball predicted to stop before reaching it.
        """
        if len(self._obs) < self.min_points:
            return None
        obs = np.asarray(self._obs)
        t, x, y = obs[:, 0], obs[:, 1], obs[:, 2]
        n = len(t)
        # 1. straight path y = a + b (x - xm), least squares, one pass of 3-sigma rejection
        keep = np.ones(n, dtype=bool)
        for _ in range(2):
            xm = x[keep].mean()
            design = np.column_stack([np.ones(keep.sum()), x[keep] - xm])
            coef, *_ = np.linalg.lstsq(design, y[keep], rcond=None)
            res = y - (coef[0] + coef[1] * (x - xm))
            sig = max(float(np.std(res[keep])), self.position_sigma * 0.1)
            new_keep = np.abs(res) <= 3.0 * sig + 1e-12
            if new_keep.sum() < self.min_points or np.array_equal(new_keep, keep):
                break
            keep = new_keep
        a, b = float(coef[0]), float(coef[1])
        dof = max(1, int(keep.sum()) - 2)
        s2 = max(float((res[keep] ** 2).sum()) / dof, self.position_sigma**2)
        cov = s2 * np.linalg.inv(design.T @ design)
        dxc = self.catch_x - xm
        y_cross = a + b * dxc
        var_y = cov[0, 0] + 2 * dxc * cov[0, 1] + dxc * dxc * cov[1, 1]
        # 2. along-track motion s(t) on the path, Gauss-Newton on (s0, v0) at t_ref = last time
        norm = math.hypot(1.0, b)
        ux, uy = 1.0 / norm, b / norm
        s = (x[keep] - xm) * ux + (y[keep] - a) * uy
        tk = t[keep]
        t_ref = float(t[-1])
        tau = tk - t_ref
        # initial guess from a straight-line fit of s(t)
        lin = np.polyfit(tau, s, 1) if len(tau) >= 2 else np.array([0.0, s[-1]])
        v_ref = float(lin[0])
        if v_ref <= 1e-6 or ux <= 0:
            return None
        s_ref = float(lin[1])
        theta = self._fit_along(tau, s, s_ref, v_ref)
        if theta is None:
            return None
        s_ref, v_ref, cov_sv = theta
        s_cross = dxc * ux + (y_cross - a) * uy
        dt = self.model.time_to_travel(v_ref, s_cross - s_ref)
        if dt is None:
            return None
        # uncertainty of the time by finite differences on (s_ref, v_ref)
        eps_s, eps_v = 1e-4, 1e-4 * max(v_ref, 1e-3)
        t1 = self.model.time_to_travel(v_ref, s_cross - s_ref - eps_s)
        t2 = self.model.time_to_travel(v_ref + eps_v, s_cross - s_ref)
        if t1 is None or t2 is None:
            var_t = 0.0
        else:
            g = np.array([(t1 - dt) / eps_s, (t2 - dt) / eps_v])
            var_t = float(g @ cov_sv @ g)
        v_cross = self.model.speed(v_ref, dt)
        return Prediction(
            x=self.catch_x,
            y=float(y_cross),
            t=t_ref + dt,
            vx=v_cross * ux,
            vy=v_cross * uy,
            sigma_y=math.sqrt(max(var_y, 0.0)),
            sigma_t=math.sqrt(max(var_t, 0.0)),
            t_obs=t_ref,
            n=int(keep.sum()),
        )

    def _fit_along(
        self, tau: np.ndarray, s: np.ndarray, s_ref: float, v_ref: float
    ) -> tuple[float, float, np.ndarray] | None:
        """Gauss-Newton for s(τ) = s_ref + D(v_ref, τ) where D is the model's distance function.

        For τ < 0 (the past) the distance is negative; D(v_ref, τ) for τ < 0 is evaluated by
        running the model backwards: the speed at τ is found from the model and the distance
        between then and now subtracted.
        """
        model = self.model

        def back_distance(v: float, taus: np.ndarray) -> np.ndarray:
            # distance from time tau (<= 0) to time 0 is D(v_tau, -tau) where v_tau solves
            # speed(v_tau, -tau) = v; invert with the time-reversed ODE dv/dτ = +(α + β v²).
            a, b = model.alpha, model.beta
            back = -taus
            if a > 0 and b > 0:
                c = math.sqrt(a * b)
                phi = math.atan(v * math.sqrt(b / a))
                phi_tau = np.minimum(phi + c * back, math.pi / 2 - 1e-9)
                dist: np.ndarray = np.log(np.cos(phi) / np.cos(phi_tau)) / b
                return dist
            if b > 0:
                return np.log(1.0 / np.maximum(1e-12, 1.0 - b * v * back)) / b
            return v * back + 0.5 * a * back**2

        theta = np.array([s_ref, v_ref], dtype=float)
        for _ in range(20):
            f = theta[0] - back_distance(theta[1], tau)
            r = s - f
            h = 1e-6 * max(1.0, abs(theta[1]))
            df_dv = (-(back_distance(theta[1] + h, tau)) - (-(back_distance(theta[1], tau)))) / h
            jac = np.column_stack([np.ones_like(tau), df_dv])
            jtj = jac.T @ jac
            try:
                step = np.linalg.solve(jtj + 1e-12 * np.eye(2), jac.T @ r)
            except np.linalg.LinAlgError:
                return None
            theta = theta + step
            if theta[1] <= 0:
                return None
            if abs(step[0]) < 1e-9 and abs(step[1]) < 1e-9:
                break
        f = theta[0] - back_distance(theta[1], tau)
        r = s - f
        dof = max(1, len(tau) - 2)
        s2 = max(float(r @ r) / dof, self.position_sigma**2)
        try:
            cov = s2 * np.linalg.inv(jtj)
        except np.linalg.LinAlgError:
            return None
        return float(theta[0]), float(theta[1]), cov
