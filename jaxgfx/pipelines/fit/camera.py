"""The fit's camera: :class:`jaxgfx.hdr.Camera` between the rendered radiance and LDR targets.

Any :class:`jaxgfx.hdr.CameraResponse` can sit in the chain: a fitted gamma, a fixed curve
(an analytic one, or one loaded from a response file / calibrate report with
:func:`jaxgfx.hdr.load_response`), or a free-form monotone table fitted jointly with the scene
(:func:`free_response`). Whatever the curve, the loss needs it only at the integer codes
(and at the two half-codes that bound a clipped or black pixel), so the fit evaluates the
response once per step on the ``2^bits`` levels — a *level table* ``G`` of ``ln f⁻¹`` —
and linearises every pixel with one gather (:func:`fit_level_table`). The three curve kinds
are blended by a one-hot weight vector and the fixed curve's table is an argument, so gamma,
analytic, loaded and free-form cameras share one compiled program, and no pixel pays for a
curve the fit does not use.

A picture style (``camera.color_matrix``, ``camera.tonemap``) joins the chain as
``codes = f(T̃(M · gains · radiance))``. The tone curve is per channel and monotone, so it
folds into the level table (``G' = ln T̃⁻¹(e^G)``, :func:`tone_level_table`: 256 values per
step, not per pixel) and a clipped code still bounds one channel; the matrix mixes channels,
so it is applied to the *render* (:func:`photo_matrix`) and the loss compares after it, in
the camera's output-linear space (a linear map of the Monte Carlo image: the loss stays
quadratic in it, hence unbiased)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import check_choice
from jaxgfx.hdr import ANALYTIC_RESPONSES, Camera, CameraResponse, ToneCurve

__all__ = [
    "RESPONSE_MODELS",
    "CURVE_KINDS",
    "fit_camera",
    "photo_camera",
    "apply_camera",
    "camera_to_linear",
    "freeze",
    "code_levels",
    "level_table",
    "free_response",
    "free_init",
    "fit_level_table",
    "response_of",
    "with_channels",
    "tone_level_table",
    "tone_curve",
    "white_preserving",
    "photo_matrix",
]

RESPONSE_MODELS = ("gamma", "table", *ANALYTIC_RESPONSES)
"""Response models of the fit's camera: ``gamma`` (a fitted exponent), ``table`` (a free-form
monotone curve, :func:`free_response`) and the fixed analytic curves of
:meth:`jaxgfx.hdr.CameraResponse.analytic` (:data:`jaxgfx.hdr.ANALYTIC_RESPONSES`); a curve
loaded from a file (``camera.response.from``) is fixed too."""

CURVE_KINDS = ("gamma", "fixed", "free")
"""The three slots of the level-table blend (:func:`fit_level_table`)."""


def fit_camera(exposure, gamma, *, model: str) -> Camera:
    """The :class:`~jaxgfx.hdr.Camera` of a gamma / analytic fit: response ``model`` anchored
    at ``"unit"`` (``response(1) = 1``; ``gamma`` is ``v = x^(1/γ)``), ``exposure`` a scalar.
    No clip, no quantisation (the loss handles both)."""
    check_choice(model, "model", tuple(m for m in RESPONSE_MODELS if m != "table"))
    if model == "gamma":
        resp = CameraResponse.gamma(jnp.reshape(gamma, (1,)), anchor="unit")
    else:
        resp = CameraResponse.analytic(model, anchor="unit")
    return Camera(resp, exposure, clip=False)


def apply_camera(radiance, exposure, gamma, *, model: str):
    """Continuous display value ``v = response(exposure · radiance)`` (not clipped, not
    quantised). ``model``: gamma or an analytic name; ``gamma`` is used by ``"gamma"`` only.
    Example: ``apply_camera(0.25, 1.0, 2.0, model="gamma")`` → 0.5."""
    return fit_camera(exposure, gamma, model=model).display(jnp.asarray(radiance))


def camera_to_linear(z, exposure, gamma, *, model: str):
    """Inverse of :func:`apply_camera`: linear radiance for display values ``z`` in [0, 1]."""
    return fit_camera(exposure, gamma, model=model).linearize(jnp.asarray(z))


def freeze(x, free):
    """``x`` with its gradient kept where ``free`` (1.0) and removed where 0.0."""
    return free * x + (1.0 - free) * jax.lax.stop_gradient(x)


# ------------------------------------------------------------------------------ level tables


def code_levels(bits: int, dtype=np.float32) -> np.ndarray:
    """The ``2^bits`` levels the loss needs, in codes: ``½, 1, 2, …, c − 1, c − ½``
    (``c = 2^bits − 1``): index ``q`` is code ``q`` for ``0 < q < c``; index 0 and ``c`` are
    the half-codes that bound a black / clipped pixel."""
    c = 2**bits - 1
    lev = np.arange(c + 1, dtype=np.float64)
    lev[0], lev[c] = 0.5, c - 0.5
    return lev.astype(dtype)


def level_table(response: CameraResponse, bits: int, dtype=jnp.float32):
    """``G[q] = ln f⁻¹(level_q)``, ``(2^bits, C)``: the relative sensor signal (``x = 1`` at
    the clipping level, the :class:`~jaxgfx.hdr.Camera` convention) that records each level of
    :func:`code_levels`. Differentiable in the response's parameters."""
    cam = Camera(response, jnp.ones((), dtype), bits=bits, clip=False)
    lev = jnp.asarray(code_levels(bits), dtype)[:, None]
    x = cam.linearize(jnp.broadcast_to(lev, (lev.shape[0], response.channels)))
    return jnp.log(jnp.maximum(x, jnp.finfo(dtype).tiny))


def free_response(u) -> CameraResponse:
    """The free-form response of a fit: a ``"table"`` :class:`~jaxgfx.hdr.CameraResponse`
    with ``K = u.shape[0] + 1`` uniform knots over ``[0, 1]``, ``ln x`` at knot ``k`` equal to
    ``−Σ_{j ≥ k} softplus(u_j)`` (0 at the clip level): strictly increasing for any ``u``
    (monotone by construction), anchored at ``"unit"``."""
    d = jax.nn.softplus(u)
    g = -jnp.cumsum(d[::-1], axis=0)[::-1]
    table = jnp.concatenate([g, jnp.zeros_like(d[:1])], axis=0)
    return CameraResponse(table, "table", "fit", 1.0, 1.0)


def free_init(start: CameraResponse, knots: int, channels: int) -> np.ndarray:
    """Unconstrained parameters ``u`` ``(knots − 1, channels)`` of :func:`free_response`
    closest to ``start`` (its ``ln x`` at the knots, increments clamped to ≥ 1e-3; knot 0 is
    taken at level ¼ of the first code step, where ``ln x`` of a real curve is finite)."""
    z = np.linspace(0.0, 1.0, knots)
    z[0] = 0.25 / 255.0
    cam = Camera(start, jnp.ones(()), clip=False)
    x = np.asarray(cam.linearize(jnp.broadcast_to(jnp.asarray(z)[:, None], (knots,
                                                                            start.channels))))
    g = np.log(np.maximum(x, 1e-30))
    g = g - g[-1:]
    if g.shape[1] != channels:
        g = np.broadcast_to(g.mean(axis=1, keepdims=True), (knots, channels))
    d = np.maximum(np.diff(g, axis=0), 1e-3)
    return np.log(np.expm1(d)).astype(np.float32)  # softplus⁻¹


def tone_curve(op: str, tone_p, free=None) -> ToneCurve:
    """The :class:`~jaxgfx.hdr.ToneCurve` ``op`` with parameters ``tone_p`` (``{name:
    scalar}``; ``free`` ``{name: 0/1}`` masks: frozen ones without gradient)."""
    if free is not None:
        tone_p = {k: freeze(v, free[k]) for k, v in tone_p.items()}
    return ToneCurve(op, dict(tone_p))


def tone_level_table(table, curve: ToneCurve):
    """The level table of the response after the tone curve ``curve``: ``ln T̃⁻¹(e^G)``
    (the output-linear signal that records each level)."""
    return jnp.log(jnp.maximum(curve.inverse(jnp.exp(table)), jnp.finfo(table.dtype).tiny))


def white_preserving(m, weight):
    """``M = P + weight · diag(1 − P·1)``: with ``weight`` 1 each row sums to 1 (a fitted
    matrix keeps white; the diagonal of ``P`` has no effect), with 0 ``P`` itself (a fixed
    matrix) — one program for both."""
    return m + weight * jnp.diag(1.0 - jnp.sum(m, axis=1))


def photo_matrix(cam_p, cam_args):
    """The camera → output matrix of the fit, white balance included: ``M · diag(wb)``
    ``(3, 3)`` (the frozen entries without gradient)."""
    free = cam_args["free"]
    m = white_preserving(freeze(cam_p["color_matrix"], free["color_matrix"]),
                         cam_args["white_preserving"])
    wb = freeze(cam_p["white_balance"], free["white_balance"])
    return m * wb[None, :]


def fit_level_table(cam_p, cam_args, bits: int, tone: str | None = None):
    """The fit's level table ``(2^bits, C)`` for camera parameters ``cam_p`` (``gamma``,
    ``curve``) and arguments ``cam_args`` (``weights`` one-hot over :data:`CURVE_KINDS`,
    ``fixed`` the fixed curve's :func:`level_table`, ``free`` masks): ``Σ weights[k] · G_k``.
    A slot of weight 0 still runs on the ``2^bits`` levels only (not per pixel). ``tone``
    (static): the tone curve's operator, its parameters ``cam_p["tone"]``
    (:func:`tone_level_table`); None: no tone curve."""
    w = cam_args["weights"]
    fixed = cam_args["fixed"]
    g = freeze(cam_p["gamma"], cam_args["free"]["gamma"])
    g_gamma = level_table(CameraResponse.gamma(jnp.reshape(g, (1,)), anchor="unit"), bits)
    u = freeze(cam_p["curve"], cam_args["free"]["curve"])
    g_free = level_table(free_response(u), bits)
    table = w[0] * g_gamma + w[1] * fixed + w[2] * g_free
    if tone is not None:
        table = tone_level_table(table, tone_curve(tone, cam_p["tone"],
                                                   cam_args["free"]["tone"]))
    return table


def with_channels(resp: CameraResponse, channels: int) -> CameraResponse:
    """``resp`` with its one curve repeated for ``channels`` channels (a curve per channel
    already: unchanged)."""
    if resp.channels == channels or resp.channels != 1:
        return resp
    params = jnp.broadcast_to(resp.params, resp.params.shape[:-1] + (channels,))
    return CameraResponse(params, resp.kind, resp.method, resp.code_max, resp.anchor,
                          resp.exposure_ratios, resp.diagnostics)


def response_of(kind: str, cam_p, fixed_response: CameraResponse | None):
    """The :class:`~jaxgfx.hdr.CameraResponse` a fit ended with (for reports and previews):
    ``kind`` in :data:`CURVE_KINDS`."""
    check_choice(kind, "kind", CURVE_KINDS)
    if kind == "gamma":
        return CameraResponse.gamma(jnp.reshape(jnp.asarray(cam_p["gamma"]), (1,)),
                                    anchor="unit")
    if kind == "free":
        return free_response(jnp.asarray(cam_p["curve"]))
    return fixed_response


def photo_camera(exposure, gamma, *, model: str, bits: int) -> Camera:
    """:func:`fit_camera` as a photo is taken: clipped to the sensor range and quantised to
    ``bits`` (synthetic LDR targets and the previews)."""
    cam = fit_camera(exposure, gamma, model=model)
    return Camera(cam.response, cam.exposure, bits=bits, clip=True)
