"""Hyperelastic models in principal log-stretches: Kirchhoff stress, its tangent and its
parameter derivatives, for homogeneous test curves and their fits.

Every model is written as a function of the principal log-stretches ``eps_i = ln lambda_i``
(shape ``(n, 3)``): the principal Kirchhoff stresses ``tau_i = lambda_i dW/dlambda_i`` (Pa,
``(n, 3)``), their derivatives ``dtau_i/deps_j`` (Pa, ``(n, 3, 3)``) and their derivatives with
respect to every coefficient (``(n, 3, m)``, Pa per unit of the coefficient). Parameter names
and energies are those of the Rust core (Pa for ``c``/``mu``, 1/Pa for ``d``):

``neo_hookean`` ``[mu]``
    incompressible ``W = mu/2 (I1 - 3)``; with a bulk modulus K, sorofem's compressible
    Neo-Hookean ``W = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2`` with ``lambda = K - 2 mu/3``
    (``sf.NeoHookean`` with its default volumetric measure ``ln J``).
``mooney_rivlin`` ``[c10, c01, d1]``
    ``W = c10 (I1b - 3) + c01 (I2b - 3) + (J - 1)^2 / d1``.
``yeoh`` ``[c10, c20, c30, d1, d2, d3]``
    ``W = sum_i ci0 (I1b - 3)^i + sum_i (J - 1)^(2i) / d_i`` (``d_i = 0``: no term).
``ogden`` with N = 1..3 terms ``[mu:0, alpha:0, ..., mu:N-1, alpha:N-1, d1]``
    ``W = sum_p 2 mu_p / alpha_p^2 (l1b^alpha_p + l2b^alpha_p + l3b^alpha_p - 3) + (J - 1)^2 / d1``.

``I1b = J^(-2/3) I1``, ``I2b = J^(-4/3) I2``, ``lib = J^(-1/3) lambda_i``. ``d1 = 0`` (every
``d_i = 0``) means incompressible: the isochoric part alone, the pressure left to the test's
boundary conditions. Small-strain shear modulus ``2 (c10 + c01)``, ``2 c10``, ``sum_p mu_p``,
``mu``; bulk modulus ``2 / d1``.

For the decoupled models (all but ``neo_hookean``) the stress is the deviatoric projection of
the isochoric part plus the volumetric part (Holzapfel, *Nonlinear Solid Mechanics*, 6.4):
``tau_i = taub_i - (1/3) sum_j taub_j + J U'(J)`` with ``taub_i = lib dWb/dlib``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..errors import ParameterError

__all__ = ["MODELS", "ModelSpec", "model_spec", "small_strain_moduli"]

Array = NDArray[np.float64]

#: The models :func:`model_spec` knows.
MODELS = ("neo_hookean", "mooney_rivlin", "yeoh", "ogden")

_DEFAULT_TERMS = {"yeoh": 3, "ogden": 3}
_MAX_TERMS = 3


@dataclass(frozen=True)
class ModelSpec:
    """A model and its parameter names in the Rust core's order.

    ``terms`` is the number of Yeoh coefficients ``ci0`` that are free (the others are 0) or
    the number of Ogden term pairs; 1 for Neo-Hookean and Mooney-Rivlin.
    """

    name: str
    terms: int
    param_names: tuple[str, ...]

    @property
    def volumetric_names(self) -> tuple[str, ...]:
        """The compliances ``d_i`` (1/Pa): never fitted, set from the bulk modulus."""
        return tuple(n for n in self.param_names if n.startswith("d"))

    @property
    def coefficient_names(self) -> tuple[str, ...]:
        """The names a fit may free: every coefficient the chosen ``terms`` use."""
        if self.name == "yeoh":
            return ("c10", "c20", "c30")[: self.terms]
        return tuple(n for n in self.param_names if not n.startswith("d"))


def model_spec(model: str, terms: int | None = None) -> ModelSpec:
    """The :class:`ModelSpec` of ``model`` with ``terms`` terms (Yeoh and Ogden only; default 3).

    Raises
    ------
    ParameterError
        Unknown model, ``terms`` given for a model without terms, or outside 1..3.
    """
    if not isinstance(model, str) or model not in MODELS:
        raise ParameterError(f"unknown model {model!r}; expected one of {', '.join(MODELS)}", "model")
    if terms is None:
        terms = _DEFAULT_TERMS.get(model, 1)
    elif model not in _DEFAULT_TERMS:
        raise ParameterError(f"terms applies to yeoh and ogden only, got terms={terms!r} for {model}", "terms")
    if isinstance(terms, bool) or not isinstance(terms, (int, np.integer)) or not 1 <= terms <= _MAX_TERMS:
        raise ParameterError(f"terms must be an integer from 1 to {_MAX_TERMS} for {model}, got {terms!r}", "terms")
    terms = int(terms)
    if model == "neo_hookean":
        names: tuple[str, ...] = ("mu",)
    elif model == "mooney_rivlin":
        names = ("c10", "c01", "d1")
    elif model == "yeoh":
        names = ("c10", "c20", "c30", "d1", "d2", "d3")
    else:
        names = tuple(n for p in range(terms) for n in (f"mu:{p}", f"alpha:{p}")) + ("d1",)
    return ModelSpec(model, terms, names)


def small_strain_moduli(spec: ModelSpec, theta: Array, bulk: float | None) -> tuple[float, float | None]:
    """``(shear modulus, bulk modulus)`` in Pa at the rest state; bulk ``None`` if incompressible."""
    p = dict(zip(spec.param_names, np.asarray(theta, dtype=np.float64)))
    if spec.name == "neo_hookean":
        return p["mu"], bulk
    if spec.name == "mooney_rivlin":
        mu = 2.0 * (p["c10"] + p["c01"])
    elif spec.name == "yeoh":
        mu = 2.0 * p["c10"]
    else:
        mu = sum(p[f"mu:{k}"] for k in range(spec.terms))
    return float(mu), (2.0 / p["d1"] if p["d1"] > 0 else None)


def kirchhoff(spec: ModelSpec, theta: Array, eps: Array, bulk: float | None) -> tuple[Array, Array, Array]:
    """Principal Kirchhoff stresses at log-stretches ``eps`` ``(n, 3)`` and their derivatives.

    ``theta`` holds every parameter in ``spec.param_names`` order. ``bulk`` is ``None`` for the
    incompressible model (no volumetric part; the stresses are then defined up to a pressure
    and only their differences are meaningful), otherwise the bulk modulus K (Pa), which the
    decoupled models take as ``2 / d1`` from ``theta`` and Neo-Hookean uses directly.

    Returns
    -------
    tau : (n, 3)
        ``tau_i = lambda_i dW/dlambda_i`` (Pa).
    dtau_deps : (n, 3, 3)
        ``d tau_i / d eps_j`` (Pa).
    dtau_dtheta : (n, 3, m)
        ``d tau_i / d theta_k`` at fixed ``eps`` (for Neo-Hookean at fixed K).
    """
    eps = np.asarray(eps, dtype=np.float64)
    theta = np.asarray(theta, dtype=np.float64)
    if spec.name == "neo_hookean":
        return _neo_hookean(theta[0], eps, bulk)
    mean = eps.mean(axis=1, keepdims=True)
    iso, diso, iso_dtheta = _isochoric(spec, theta, eps - mean)
    n = eps.shape[0]
    proj = np.eye(3) - 1.0 / 3.0
    tau = iso @ proj
    dtau_deps = proj @ diso @ proj
    dtau_dtheta = np.einsum("ij,njk->nik", proj, iso_dtheta)
    if bulk is not None:
        d = dict(zip(spec.param_names, theta))
        log_j = 3.0 * mean[:, 0]
        jm1 = np.expm1(log_j)
        j = jm1 + 1.0
        dU = np.zeros(n)
        d2U = np.zeros(n)
        for i in (1, 2, 3):
            di = d.get(f"d{i}", 0.0)
            if di == 0.0:
                continue
            dU += 2 * i * jm1 ** (2 * i - 1) / di
            d2U += 2 * i * (2 * i - 1) * jm1 ** (2 * i - 2) / di
            k = spec.param_names.index(f"d{i}")
            dtau_dtheta[:, :, k] += (-j * 2 * i * jm1 ** (2 * i - 1) / di**2)[:, None]
        tau = tau + (j * dU)[:, None]
        dtau_deps = dtau_deps + (j * (dU + j * d2U))[:, None, None]
    return tau, dtau_deps, dtau_dtheta


def _neo_hookean(mu: float, eps: Array, bulk: float | None) -> tuple[Array, Array, Array]:
    """sorofem's Neo-Hookean: ``tau_i = mu (lambda_i^2 - 1) + lambda ln J``, ``lambda = K - 2 mu/3``."""
    sq = np.exp(2.0 * eps)
    tau = mu * (sq - 1.0)
    dtau = np.zeros(eps.shape + (3,))
    idx = np.arange(3)
    dtau[:, idx, idx] = 2.0 * mu * sq
    dtheta = (sq - 1.0)[:, :, None]
    if bulk is not None:
        lame = bulk - 2.0 * mu / 3.0
        log_j = eps.sum(axis=1)
        tau = tau + (lame * log_j)[:, None]
        dtau = dtau + lame
        dtheta = dtheta - (2.0 / 3.0) * log_j[:, None, None]
    return tau, dtau, dtheta


def _isochoric(spec: ModelSpec, theta: Array, ebar: Array) -> tuple[Array, Array, Array]:
    """``taub_i = lib dWb/dlib`` at isochoric log-stretches ``ebar``, ``d taub_i / d ebar_j`` and
    ``d taub_i / d theta_k``."""
    n = ebar.shape[0]
    m = len(spec.param_names)
    dtheta = np.zeros((n, 3, m))
    idx = np.arange(3)
    if spec.name == "ogden":
        tau = np.zeros((n, 3))
        dtau = np.zeros((n, 3, 3))
        for p in range(spec.terms):
            mu, alpha = theta[2 * p], theta[2 * p + 1]
            power = np.exp(alpha * ebar)
            tau += 2.0 * mu / alpha * power
            dtau[:, idx, idx] += 2.0 * mu * power
            dtheta[:, :, 2 * p] = 2.0 / alpha * power
            dtheta[:, :, 2 * p + 1] = 2.0 * mu / alpha * power * (ebar - 1.0 / alpha)
        return tau, dtau, dtheta

    # Invariant models: taub_i = W1 a_i + W2 b_i with a_i = dI1b/debar_i = 2 lib^2 and
    # b_i = dI2b/debar_i = a_i (I1b - a_i/2).
    a = 2.0 * np.exp(2.0 * ebar)
    i1 = 0.5 * a.sum(axis=1)
    b = a * (i1[:, None] - 0.5 * a)
    p = dict(zip(spec.param_names, theta))
    zero = np.zeros(n)
    if spec.name == "mooney_rivlin":
        w1, w2, w11 = p["c10"] + zero, p["c01"] + zero, zero
        dw1 = {"c10": 1.0 + zero}
        dw2 = {"c01": 1.0 + zero}
    else:  # yeoh
        x = i1 - 3.0
        w1 = p["c10"] + 2.0 * p["c20"] * x + 3.0 * p["c30"] * x**2
        w11 = 2.0 * p["c20"] + 6.0 * p["c30"] * x
        w2 = zero
        dw1 = {"c10": 1.0 + zero, "c20": 2.0 * x, "c30": 3.0 * x**2}
        dw2 = {}
    tau = w1[:, None] * a + w2[:, None] * b
    outer_aa = a[:, :, None] * a[:, None, :]
    dtau = w11[:, None, None] * outer_aa + w2[:, None, None] * outer_aa
    diag = 2.0 * w1[:, None] * a + w2[:, None] * (2.0 * a * i1[:, None] - 2.0 * a**2)
    dtau[:, idx, idx] += diag
    for name, value in dw1.items():
        dtheta[:, :, spec.param_names.index(name)] += value[:, None] * a
    for name, value in dw2.items():
        dtheta[:, :, spec.param_names.index(name)] += value[:, None] * b
    return tau, dtau, dtheta
