"""A small bounded robust least-squares solver: the cloud skeleton's trunk cylinder fit without scipy.optimize, whose
import alone costs a cloud reconstruction's command a noticeable share of its start-up.

In: a residual function of a few parameters, a start, box bounds and a scale. Out: the parameters minimising the
soft-L1 loss sum 2 (sqrt(1 + (r / f)^2) - 1), which treats residuals beyond f almost linearly (branch stubs on a
trunk's bark do not pull the fit), inside the box.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

__all__ = ["soft_l1_fit"]


def _soft_l1(residual: np.ndarray, scale: float) -> float:
    return float(2.0 * np.sum(np.sqrt(1.0 + (residual / scale) ** 2) - 1.0))


def soft_l1_fit(residual: Callable[[np.ndarray], np.ndarray], start: np.ndarray, lower: np.ndarray,
                upper: np.ndarray, scale: float, max_steps: int = 50) -> np.ndarray:
    """Parameters in [lower, upper] (a parameter with lower == upper stays fixed) minimising the soft-L1 loss of
    `residual(x)` at scale `scale`: damped Gauss-Newton (Levenberg-Marquardt) on the loss's reweighted squares,
    forward-difference Jacobian, each step clipped into the box; at most `max_steps` steps are taken."""
    x = np.clip(np.asarray(start, np.float64), lower, upper)
    r = residual(x)
    cost = _soft_l1(r, scale)
    free = upper > lower
    damping = 1e-3
    for _ in range(max_steps):
        weight = 1.0 / np.sqrt(1.0 + (r / scale) ** 2)
        h = 1e-7 * np.maximum(1.0, np.abs(x))
        jacobian = np.zeros((len(r), len(x)))
        for k in np.flatnonzero(free):
            moved = x.copy()
            moved[k] += h[k]
            jacobian[:, k] = (residual(moved) - r) / h[k]
        normal = jacobian.T @ (weight[:, None] * jacobian)
        gradient = jacobian.T @ (weight * r)
        # A parameter on its bound that the loss pushes further out stays there this step (an active bound).
        moving = free & ~(((x <= lower) & (gradient > 0)) | ((x >= upper) & (gradient < 0)))
        if not moving.any():
            break
        improved = False
        while damping < 1e10:
            system = normal + damping * np.diag(np.diag(normal) + 1e-12)
            step = np.zeros_like(x)
            step[moving] = np.linalg.solve(system[np.ix_(moving, moving)], -gradient[moving])
            trial = np.clip(x + step, lower, upper)
            trial_r = residual(trial)
            trial_cost = _soft_l1(trial_r, scale)
            if trial_cost < cost:
                improved = True
                break
            damping *= 10.0
        if not improved:
            break
        gain = cost - trial_cost
        x, r, cost = trial, trial_r, trial_cost
        damping = max(damping * 0.1, 1e-12)
        if gain <= 1e-12 * max(cost, 1e-30):
            break
    return x
