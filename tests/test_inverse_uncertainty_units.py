"""The Gauss-Newton uncertainty does not depend on the units of the optimiser's variables: a
log-space modulus (per relative change) beside a sign-free coefficient (per Pa) used to make a
well-determined coefficient look non-identifiable (issue 15's Yeoh hammerbot fit)."""

from __future__ import annotations

import numpy as np

from sorofem.inverse._optimizers import uncertainty


def _data(column_scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(7)
    jacobian = rng.normal(size=(40, 2))
    jacobian[:, 1] *= column_scale
    residual = 1e-3 * rng.normal(size=40)
    return jacobian, residual, np.array([1.6e4, 6.8e3])


def test_a_per_pascal_column_is_as_determined_as_the_data_make_it() -> None:
    jacobian, residual, theta = _data(1e-9)
    unc = uncertainty(["c10", "c20"], theta, np.ones(2), residual, jacobian, 40)
    sigma2 = residual @ residual / (40 - 2)
    expected = np.sqrt(np.diag(np.linalg.inv(jacobian.T @ jacobian)) * sigma2)
    np.testing.assert_allclose(unc.std, expected, rtol=1e-9)
    assert not np.any(np.isinf(unc.std))


def test_the_answer_scales_with_the_column_and_a_dependent_column_is_weak() -> None:
    base = uncertainty(["a", "b"], *_scaled(1.0))
    scaled = uncertainty(["a", "b"], *_scaled(1e-9))
    np.testing.assert_allclose(scaled.std, base.std * np.array([1.0, 1e9]), rtol=1e-9)
    jacobian, residual, theta = _data(1.0)
    jacobian[:, 1] = 1e-9 * jacobian[:, 0]
    dependent = uncertainty(["a", "b"], theta, np.ones(2), residual, jacobian, 40)
    assert np.all(np.isinf(dependent.std))


def _scaled(scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    jacobian, residual, theta = _data(scale)
    return theta, np.ones(2), residual, jacobian, 40
