"""Specification of reconstruct.robust_fit: bounded soft-L1 least squares."""
import numpy as np

from reconstruct.robust_fit import soft_l1_fit


def line_with_outliers(rng):
    x = np.linspace(0.0, 10.0, 200)
    y = 0.5 * x + 2.0 + rng.normal(0.0, 0.01, len(x))
    y[::10] += 5.0  # a tenth of the points far off, as branch stubs are beside a trunk's bark
    return x, y


def test_the_fit_ignores_far_outliers_that_pull_plain_least_squares():
    x, y = line_with_outliers(np.random.default_rng(0))
    fitted = soft_l1_fit(lambda p: p[0] * x + p[1] - y, np.zeros(2), np.full(2, -10.0), np.full(2, 10.0), 0.05)
    plain = np.polyfit(x, y, 1)
    assert abs(fitted[0] - 0.5) < 0.005 and abs(fitted[1] - 2.0) < 0.02
    assert abs(plain[1] - 2.0) > 0.3  # what the outliers do without the soft-L1 loss


def test_the_fit_stays_in_its_box_and_keeps_a_pinned_parameter():
    x, y = line_with_outliers(np.random.default_rng(1))
    fitted = soft_l1_fit(lambda p: p[0] * x + p[1] - y, np.array([0.0, 1.0]), np.array([-1.0, 1.0]),
                         np.array([0.4, 1.0]), 0.05)
    assert fitted[0] == 0.4 and fitted[1] == 1.0  # the slope on its upper bound; the intercept pinned
