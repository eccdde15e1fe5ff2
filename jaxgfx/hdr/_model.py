"""The :class:`CameraResponse` model (see :mod:`jaxgfx.hdr.response`).

Conventions
-----------
* Pixel levels ``z`` are given in the units of the input images: integer codes for uint8 /
  uint16 data (0…255, 0…65535), or floats in ``[0, 1]``. Internally they are normalised to
  ``[0, 1]`` by ``code_max`` (255, 65535 or 1).
* ``to_linear(z)`` returns *relative* linear exposure (irradiance × time, arbitrary unit) per
  channel; the unit is fixed by an explicit anchor: by default ``to_linear(0.5 * code_max) = 1``
  (``anchor="mid"``, Debevec & Malik's ``g(Z_mid) = 0``); ``anchor="unit"`` gives
  ``to_linear(code_max) = 1``; a float in ``(0, 1]`` anchors that normalised level.
* ``log_exposure`` is ``ln to_linear`` tabulated on the level grid (Debevec's ``g``).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array

from .._checks import check_choice
from ._curves import ANALYTIC_KINDS, base_from_linear, base_to_linear

__all__ = ["CameraResponse", "resolve_anchor", "RESPONSE_KINDS"]

RESPONSE_KINDS = ("table", "gamma", "polynomial", *ANALYTIC_KINDS)
"""Curve families of :class:`CameraResponse` (fitted tables, power laws, polynomials and the
analytic curves of :data:`jaxgfx.hdr.ANALYTIC_RESPONSES`)."""


def resolve_anchor(anchor) -> float:
    """Normalised anchor level: ``"mid"`` → 0.5, ``"unit"`` → 1.0, or a float in (0, 1]."""
    if isinstance(anchor, str):
        check_choice(anchor, "anchor", ("mid", "unit"))
        return 0.5 if anchor == "mid" else 1.0
    if isinstance(anchor, bool) or not isinstance(anchor, (int, float)):
        raise TypeError(f"anchor: expected 'mid', 'unit' or a float in (0, 1], got {anchor!r}")
    if not 0.0 < float(anchor) <= 1.0:
        raise ValueError(f"anchor: expected a normalised level in (0, 1], got {anchor}")
    return float(anchor)


class CameraResponse(eqx.Module):
    """A per-channel camera response ``z ↦ x`` (pixel level → relative linear exposure).

    Fields:
      * ``params``: the differentiable curve parameters; shape depends on ``kind``:
        ``"table"`` ``(L, C)`` ln-exposure at ``L`` uniform knots over ``[0, 1]``
        (piecewise-linear in the log domain); ``"gamma"`` ``(C,)`` exponents
        (``x = z^γ``); ``"polynomial"`` ``(K+1, C)`` coefficients ``c_k`` of
        ``x = Σ c_k z^k`` (Mitsunaga & Nayar 1999); analytic kinds (``"srgb"``,
        ``"s-curve"``, ``"filmic"``, ``"log"``: ground-truth curves) ``(C,)`` unused.
      * ``kind`` / ``method`` (static): curve family and the method that produced it.
      * ``code_max`` (static): 255, 65535 or 1.0, the input unit of ``z``.
      * ``anchor`` (static): normalised level ``z_a`` with ``to_linear(z_a · code_max) = 1``.
      * ``exposure_ratios``: ``(N,)`` fitted exposure times relative to the shortest
        (sorted ascending), or ``None`` when times were taken as given.
      * ``diagnostics``: dict of arrays (residual RMS, convergence history, ...).

    Example: ``CameraResponse.gamma(2.0).to_linear(0.25)`` → ``0.25`` (anchor "mid":
    ``(0.25 / 0.5)^2``).
    """

    params: Array
    kind: str = eqx.field(static=True)
    method: str = eqx.field(static=True, default="")
    code_max: float = eqx.field(static=True, default=1.0)
    anchor: float = eqx.field(static=True, default=0.5)
    exposure_ratios: Array | None = None
    diagnostics: dict = eqx.field(default_factory=dict)

    def __check_init__(self):
        check_choice(self.kind, "kind", RESPONSE_KINDS)

    # -- constructors -----------------------------------------------------------------------
    @classmethod
    def gamma(cls, gamma, *, channels: int = 1, code_max: float = 1.0, anchor="mid"):
        """Power-law response ``x ∝ z^gamma`` (``gamma`` scalar or ``(C,)``)."""
        g = jnp.broadcast_to(jnp.asarray(gamma, dtype=jnp.result_type(float)), (channels,))
        if jnp.ndim(gamma) == 1:
            g = jnp.asarray(gamma, dtype=jnp.result_type(float))
        return cls(g, "gamma", "gamma", float(code_max), resolve_anchor(anchor))

    @classmethod
    def analytic(cls, name: str, *, channels: int = 1, code_max: float = 1.0, anchor="mid"):
        """One of the analytic curves ``"srgb"``, ``"s-curve"``, ``"filmic"``, ``"log"``."""
        check_choice(name, "name", tuple(ANALYTIC_KINDS))
        z = jnp.zeros((channels,), jnp.result_type(float))
        return cls(z, name, name, float(code_max), resolve_anchor(anchor))

    # -- evaluation ---------------------------------------------------------------------------
    @property
    def channels(self) -> int:
        return int(self.params.shape[-1])

    def to_linear_normalized(self, zn):
        """``to_linear`` for normalised levels ``zn`` in ``[0, 1]``."""
        za = jnp.asarray(self.anchor, self.params.dtype)
        if self.kind == "table":
            from ._curves import table_lookup

            ga = table_lookup(za, self.params)
            return jnp.exp(table_lookup(zn, self.params) - ga)
        xa = base_to_linear(self.kind, self.params, za)
        return base_to_linear(self.kind, self.params, zn) / xa

    def from_linear_normalized(self, x):
        """Inverse of :meth:`to_linear_normalized` (result in ``[0, 1]`` for table kinds)."""
        za = jnp.asarray(self.anchor, self.params.dtype)
        xa = base_to_linear(self.kind, self.params, za)
        return base_from_linear(self.kind, self.params, jnp.asarray(x) * xa)

    def to_linear(self, z):
        """Relative linear exposure for pixel level ``z`` (input units), shape ``(..., C)``.

        Differentiable in ``z`` and in ``params``; monotone non-decreasing.
        """
        z = jnp.asarray(z)
        if not jnp.issubdtype(z.dtype, jnp.floating):
            z = z.astype(self.params.dtype)
        return self.to_linear_normalized(z / self.code_max)

    def from_linear(self, x):
        """Pixel level (input units) that records relative exposure ``x``; inverse of
        :meth:`to_linear` on the curve's range (tables clamp outside it)."""
        return self.from_linear_normalized(x) * self.code_max

    def derivative_normalized(self, zn):
        """``d to_linear / d zn`` (per normalised level), elementwise."""
        _, dx = jax.jvp(self.to_linear_normalized, (zn,), (jnp.ones_like(zn),))
        return dx

    @property
    def log_exposure(self):
        """``ln to_linear`` on the level grid: ``(L, C)`` (the knots for tables; 256 levels
        for parametric kinds)."""
        n = self.params.shape[0] if self.kind == "table" else 256
        zn = jnp.linspace(0.0, 1.0, n, dtype=self.params.dtype)[:, None]
        x = self.to_linear_normalized(jnp.broadcast_to(zn, (n, self.channels)))
        return jnp.log(jnp.maximum(x, jnp.finfo(x.dtype).tiny))

    @property
    def residuals(self):
        """RMS residual of the fit per channel (``diagnostics["residual_rms"]``), if any."""
        return self.diagnostics.get("residual_rms")
