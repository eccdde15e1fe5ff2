"""Ghost-free merge (jaxgfx.hdr.merge_deghosted) and RAW alignment (align_raw_stack).

References: the ground-truth radiance each frame saw (synthetic brackets with a moving
object), the oracle merge that knows which frames saw the reference's content, the
chi-square distribution of the consistency statistic under the noise model, closed-form
shifts of band-limited textures, finite differences.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from jaxgfx import hdr
from jaxgfx.hdr.synthetic import make_moving_object_stack

H = W = 48
REF = 2
T = 4.0 ** np.arange(-2, 3)


def _log_err(R, truth, static):
    """|ln R - ln truth| after the median log ratio of the static pixels (the response's
    exposure unit is arbitrary), max over channels."""
    d = np.log(np.maximum(np.asarray(R, np.float64), 1e-30)) - np.log(np.asarray(truth))
    d = np.abs(d - np.median(d[static]))
    return d.max(-1)


@pytest.fixture(scope="module")
def moving():
    """8-bit sRGB bracket of a 1e3:1 scene, 5 frames 2 stops apart; a textured disc crosses the
    image (a different position in every frame); read noise 1e-3, shot noise gain 1e-4."""
    E = hdr.synthetic_radiance(jax.random.key(0), H, W, dynamic_range=1e3)
    resp = hdr.synthetic_response("srgb")
    centers = [(30, 9 + 8 * j) for j in range(5)]
    ms = make_moving_object_stack(
        jax.random.key(1), E, T, resp, centers=centers, radius=5, level=0.05
    )
    fr = np.asarray(ms.frames_radiance)
    same = np.all(fr == fr[REF][None], -1)  # (N, H, W): frame j saw the reference's content
    return ms, resp, same


# 6.9 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_moving_object_merged_without_ghosts(moving):
    ms, resp, same = moving
    imgs, noise = ms.stack.images, ms.stack.noise
    truth = ms.frames_radiance[REF]
    region = ~same.all(0)  # where any frame saw something else: the moving region
    static = ~region
    res = hdr.merge_deghosted(imgs, T, resp, noise=noise, reference=REF)
    plain = hdr.merge_radiance(imgs, T, resp, weighting="noise", noise=noise)
    # oracle: the same noise-optimal merge of exactly the frames that saw the reference's
    # content (level 0 is excluded by the weighting)
    masked = np.where(same[..., None], np.asarray(imgs), 0).astype(np.uint8)
    oracle = hdr.merge_radiance(masked, T, resp, weighting="noise", noise=noise)
    e_dg, e_pl, e_or = (_log_err(r, truth, static) for r in (res.radiance, plain, oracle))
    med = {
        k: float(np.median(e[m]))
        for k, e, m in (
            ("static", e_dg, static),
            ("moving", e_dg, region),
            ("oracle", e_or, region),
            ("plain", e_pl, region),
        )
    }
    # measured (48 x 48): static 0.012, moving 0.019, oracle 0.016, plain 0.07
    assert med["moving"] <= 1.3 * med["oracle"], med
    assert med["moving"] <= 2.0 * med["static"], med
    assert med["plain"] >= 3.0 * med["static"], med  # the plain merge has ghosts: can fail
    # no semi-transparent copy where the object was in other frames only (ghost positions)
    ghost = region & ~np.asarray(ms.object_masks[REF])
    assert np.percentile(e_dg[ghost], 95) < 0.15, np.percentile(e_dg[ghost], 95)
    assert np.percentile(e_pl[ghost], 95) > 0.5
    # the object itself is there, at full strength, where the reference saw it
    obj = np.asarray(ms.object_masks[REF])
    assert np.percentile(e_dg[obj], 95) < 0.15
    # the map of frames: the reference nearly everywhere; a frame whose object is well above
    # its noise (the longer ones) is not used where its object was
    used = np.asarray(res.used)
    assert used.shape == (5, H, W) and used[REF].mean() > 0.95
    for j in (3, 4):
        assert used[j][np.asarray(ms.object_masks[j]) & ~obj].mean() < 0.02, j
    assert np.isfinite(np.asarray(res.variance)).all()


def test_static_scene_equals_the_noise_optimal_merge(moving):
    """No motion: every frame is consistent and the result is merge_radiance(weighting="noise")."""
    ms, resp, _ = moving
    E = ms.stack.radiance
    still = make_moving_object_stack(
        jax.random.key(1), E, T, resp, centers=[(30, 24)] * 5, radius=5, level=0.05
    )
    res = hdr.merge_deghosted(still.stack.images, T, resp, noise=still.stack.noise)
    plain = hdr.merge_radiance(still.stack.images, T, resp, weighting="noise", noise=ms.stack.noise)
    close = np.isclose(np.asarray(res.radiance), np.asarray(plain), rtol=1e-5).all(-1)
    assert close.mean() > 0.97, close.mean()
    e = _log_err(res.radiance, still.frames_radiance[0], np.ones((H, W), bool))
    e0 = _log_err(plain, still.frames_radiance[0], np.ones((H, W), bool))
    assert np.median(e) <= 1.02 * np.median(e0)


def test_statistic_is_chi_square_per_channel_under_the_noise_model():
    """Float linear frames, no clipping, every value bright: per pixel (sigma = 0) the statistic
    is a chi-square with C = 3 degrees of freedom over C, mean 1, variance 2 / C."""
    rng = np.random.default_rng(0)
    E = jnp.asarray(rng.uniform(0.2, 0.4, (32, 32, 3)), jnp.float32)
    t = np.array([0.5, 1.0, 2.0])
    lin = hdr.CameraResponse.gamma(1.0, channels=3, anchor="unit")
    st = hdr.make_bracketed_stack(
        jax.random.key(3), E, t, lin, bits=None, gain=1e-3, read_sigma=1e-2
    )
    res = hdr.merge_deghosted(st.images, t, None, noise=st.noise, reference=1, sigma=0.0)
    s = np.asarray(res.statistic)[[0, 2]]
    m = s.size
    assert abs(s.mean() - 1.0) < 4 * np.sqrt(2 / 3 / m), s.mean()
    assert abs(s.var() - 2 / 3) < 0.15, s.var()
    assert (np.asarray(res.statistic)[1] == 0).all()


# 3.4 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_raw_path_moving_object():
    """Linear RAW frames (float, 1 = white level, response=None): the same ghost removal."""
    E = hdr.synthetic_radiance(jax.random.key(0), H, W, dynamic_range=1e3)
    lin = hdr.CameraResponse.gamma(1.0, channels=3, anchor="unit")
    ms = make_moving_object_stack(
        jax.random.key(2),
        E,
        T,
        lin,
        centers=[(30, 9 + 8 * j) for j in range(5)],
        radius=5,
        level=0.05,
        bits=None,
    )
    fr = np.asarray(ms.frames_radiance)
    same = np.all(fr == fr[REF][None], -1)
    region, static = ~same.all(0), same.all(0)
    res = hdr.merge_deghosted(ms.stack.images, T, None, noise=ms.stack.noise, reference=REF)
    plain = hdr.merge_radiance(ms.stack.images, T, lin, weighting="noise", noise=ms.stack.noise)
    e_dg = _log_err(res.radiance, fr[REF], static)
    e_pl = _log_err(plain, fr[REF], static)
    ghost = region & ~np.asarray(ms.object_masks[REF])
    masked = np.where(same[..., None], np.asarray(ms.stack.images), 0.0)  # the oracle
    oracle = hdr.merge_radiance(masked, T, lin, weighting="noise", noise=ms.stack.noise)
    e_or = _log_err(oracle, fr[REF], static)
    # measured (48 x 48): 95th percentile at the ghost positions 0.12 (oracle 0.07, plain 1.3)
    g95 = np.percentile(e_dg[ghost], 95)
    assert g95 < 0.15 and g95 < 2.0 * np.percentile(e_or[ghost], 95), g95
    assert np.percentile(e_pl[ghost], 95) > 0.5
    assert np.median(e_dg[region]) < 2.0 * np.median(e_dg[static])


def test_reference_changes_per_region_where_it_is_clipped(moving):
    """Longest frame as the global reference: where it is clipped over a region, the region's
    reference is a shorter frame and the radiance stays right."""
    ms, resp, same = moving
    res = hdr.merge_deghosted(ms.stack.images, T, resp, noise=ms.stack.noise, reference=4)
    z4 = np.asarray(ms.stack.images[4])
    clipped = (z4 == 255).all(-1)
    ref = np.asarray(res.reference)
    from scipy import ndimage

    core = ndimage.binary_erosion(clipped, iterations=4)
    assert core.sum() > 20
    assert (ref[core] < 4).all()
    assert (ref[ndimage.binary_erosion(~clipped, iterations=6)] == 4).mean() > 0.95
    truth = np.asarray(ms.frames_radiance[4])
    static = same.all(0)
    e = _log_err(res.radiance, truth, static & ~clipped)
    assert np.median(e[core]) < 0.05, np.median(e[core])


def _small_moving_stack():
    rng = np.random.default_rng(1)
    E = rng.uniform(0.05, 0.3, (12, 12, 1))
    E[3:7, 3:7] = 0.9  # a bright patch in frame 1 only: a moving object
    t = np.array([0.5, 1.0, 2.0])
    frames = np.clip(np.stack([E * tt for tt in t]), 0, 1)
    frames[1, 3:7, 3:7] = 0.1
    frames = frames + 1e-3 * rng.standard_normal(frames.shape)
    frames = np.clip(frames, 0, 1)
    noise = hdr.NoiseModel(jnp.array([1e-4]), jnp.array([1e-6]))
    w = jnp.asarray(rng.random((12, 12, 1)))
    return frames, t, noise, w


# 3.6 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_jit_matches_eager_and_drops_the_object():
    frames, t, noise, _ = _small_moving_stack()
    resp = hdr.CameraResponse.gamma(1.0, channels=1, anchor="unit")
    eager = hdr.merge_deghosted(jnp.asarray(frames), t, resp, noise=noise, reference=0)
    jitted = jax.jit(lambda fr, tt: hdr.merge_deghosted(fr, tt, resp, noise=noise, reference=0))
    out = jitted(jnp.asarray(frames), jnp.asarray(t))
    np.testing.assert_allclose(out.radiance, eager.radiance, rtol=1e-6)
    used = np.asarray(eager.used)
    assert used[1, 4:6, 4:6].max() == 0 and used[1, 11, 11] == 1  # object dropped, rest kept
    np.testing.assert_allclose(np.asarray(eager.radiance)[4:6, 4:6, 0], 0.9, rtol=0.02)


@pytest.mark.slow  # ~25 s on the loaded 2-core machine (x64 compile of the merge's gradient)
def test_gradients_match_finite_differences(x64):
    """Float levels, linear response: d(sum w * radiance)/d(exposure times, response gamma)
    against central differences (the frame choice is fixed by the data)."""
    frames, t, noise, w = _small_moving_stack()

    def f(tt, g):
        resp = hdr.CameraResponse.gamma(g, channels=1, anchor="unit")
        r = hdr.merge_deghosted(jnp.asarray(frames), tt, resp, noise=noise, reference=0)
        return jnp.sum(w * r.radiance)

    args = (jnp.asarray(t), jnp.asarray(1.0))  # the true response: every frame used somewhere
    g = jax.grad(f, argnums=(0, 1))(*args)
    assert all(np.all(np.isfinite(a)) and np.all(np.abs(a) > 0) for a in g)
    check_grads(f, args, order=1, modes=("rev",), eps=1e-6, atol=1e-6, rtol=1e-5)


def test_bad_input_raises_one_clear_error():
    fr = np.full((2, 8, 8), 0.3, np.float32)
    t = np.array([1.0, 2.0])
    resp = hdr.CameraResponse.gamma(1.0)
    nm = hdr.NoiseModel(1e-4, 1e-6)
    with pytest.raises(TypeError, match="response"):
        hdr.merge_deghosted(fr, t, "srgb")
    with pytest.raises(ValueError, match="noise"):
        hdr.merge_deghosted(fr, t, None)
    with pytest.raises(ValueError, match="reference"):
        hdr.merge_deghosted(fr, t, resp, reference=2)
    with pytest.raises(ValueError, match="threshold"):
        hdr.merge_deghosted(fr, t, resp, threshold=0.0)
    with pytest.raises(ValueError, match="sigma"):
        hdr.merge_deghosted(fr, t, resp, sigma=-1.0)
    with pytest.raises(ValueError, match="exposure_times"):
        hdr.merge_deghosted(fr, t[:1], None, noise=nm)
    with pytest.raises(ValueError, match="exposure_times"):
        hdr.merge_deghosted(fr, -t, None, noise=nm)
    with pytest.raises(ValueError, match="images"):
        hdr.merge_deghosted(np.where(fr > 0, np.nan, fr), t, None, noise=nm)
    with pytest.raises(ValueError, match="saturation"):
        hdr.merge_deghosted(fr, t, None, noise=nm, saturation=1.5)


# ----------------------------------------------------------------------------- RAW alignment


def _texture(n, seed):
    rng = np.random.default_rng(seed)
    f = np.fft.fft2(rng.standard_normal((n, n)))
    k2 = np.fft.fftfreq(n)[:, None] ** 2 + np.fft.fftfreq(n)[None, :] ** 2
    tex = np.real(np.fft.ifft2(f * np.exp(-k2 / (2 * 0.08**2))))
    return 0.02 + 0.3 * ((tex - tex.min()) / (tex.max() - tex.min())) ** 2


def _fshift(img, dy, dx):
    k0, k1 = np.fft.fftfreq(img.shape[0]), np.fft.fftfreq(img.shape[1])
    ph = np.exp(-2j * np.pi * (k0[:, None] * dy + k1[None, :] * dx))
    return np.real(np.fft.ifft2(np.fft.fft2(img) * ph))


# 3.0 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
@pytest.mark.parametrize("shift", [(4.0, -6.0), (3.0, 1.5)])
def test_align_raw_stack_recovers_mosaic_shifts(shift):
    """A band-limited scene under an RGGB tile (gains 0.5 / 1 / 1 / 0.7), 3 exposures 2 stops
    apart (the longest clipped), the middle one the reference; frames 0 and 2 moved by the
    closed-form Fourier shift ``shift`` and ``-shift / 2``."""
    n, c = 128, 16
    base = _texture(n, 0)
    tile = np.array([[0.5, 1.0], [1.0, 0.7]])
    gains = np.tile(tile, (n // 2, n // 2))
    rng = np.random.default_rng(5)
    moves = [shift, (0.0, 0.0), (-shift[0] / 2, -shift[1] / 2)]
    frames = []
    for k, (dy, dx) in enumerate(moves):
        scene = _fshift(base, dy, dx) * 4.0 ** (k - 1)
        m = scene * gains + 2e-3 * rng.standard_normal((n, n))
        frames.append(np.clip(m, 0.0, 1.0)[c:-c, c:-c])
    frames = np.stack(frames).astype(np.float32)
    aligned, shifts = hdr.align_raw_stack(frames, cfa_pattern="RGGB")
    # estimated on the half-resolution tiles (0.1 tile = 0.2 px); measured errors <= 0.24 px,
    # the largest on the short, noisy frame (signal 0.005-0.08, noise 0.002)
    np.testing.assert_allclose(np.asarray(shifts), np.array(moves), atol=0.3)
    # the aligned mosaics agree with the reference (interior, same CFA tile), far better than
    # the unaligned ones (bilinear interpolation on each half-resolution CFA plane)
    inner = (slice(12, -12), slice(12, -12))
    ref = frames[1][inner]
    ok = ref > 0.01

    def rel(a):
        return np.median(np.abs(a[inner][ok] * 4.0 / ref[ok] - 1))

    assert rel(np.asarray(aligned[0])) < 0.1 and rel(frames[0]) > 3 * rel(np.asarray(aligned[0]))
    # linear frames without a CFA: the same shifts
    lin = np.stack(
        [_fshift(base, dy, dx)[c:-c, c:-c] * 4.0 ** (k - 1) for k, (dy, dx) in enumerate(moves)]
    ).astype(np.float32)
    _, s2 = hdr.align_raw_stack(np.clip(lin, 0, 1))
    np.testing.assert_allclose(np.asarray(s2), np.array(moves), atol=0.15)


def test_align_raw_stack_bad_input():
    with pytest.raises(ValueError, match="frames"):
        hdr.align_raw_stack(np.zeros((2, 9, 8), np.float32), cfa_pattern="RGGB")
    with pytest.raises(ValueError, match="cfa_pattern"):
        hdr.align_raw_stack(np.zeros((2, 8, 8), np.float32), cfa_pattern="XYZW")
    with pytest.raises(ValueError, match="frames"):
        hdr.align_raw_stack(np.zeros((1, 8, 8), np.float32))
    with pytest.raises(ValueError, match="reference"):
        hdr.align_raw_stack(np.zeros((2, 8, 8), np.float32), reference=5)
