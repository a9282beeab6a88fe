"""fBm by spectral synthesis (Geng, Hu & Zhang 2014, sec. 3): spectrum, normalisation, eq. 3, CPU/GPU parity."""

import numpy as np
import pytest

from leafview import fbm_noise
from leafview.deform.fbm import hash_uniform, pcg, resample, sample_periodic, spectrum


@pytest.mark.parametrize("beta", [1.0, 2.0, 3.0])
def test_power_spectrum_slope_is_minus_beta(beta):
    n, seeds = 512, 200
    power = np.zeros(n // 2 + 1)
    for seed in range(seeds):
        power += np.abs(np.fft.rfft(fbm_noise(n, beta, seed))) ** 2
    f = np.arange(1, n // 2)
    slope = np.polyfit(np.log(f), np.log(power[1:n // 2]), 1)[0]
    assert slope == pytest.approx(-beta, abs=0.15)


def test_signal_is_normalised_real_and_seeded():
    a = fbm_noise(256, 1.5, 42)
    assert a.shape == (256,) and a.dtype == np.float64
    assert abs(a.mean()) < 1e-12 and a.std() == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_array_equal(a, fbm_noise(256, 1.5, 42))
    assert np.abs(a - fbm_noise(256, 1.5, 43)).max() > 0.5


def test_same_random_numbers_give_the_same_macro_shape_across_beta():
    """The paper's Fig. 3: one seed, different β, similar large-scale shape."""
    smooth, rough = fbm_noise(512, 3.0, 5), fbm_noise(512, 1.0, 5)
    assert np.corrcoef(smooth, rough)[0, 1] > 0.3
    assert abs(np.corrcoef(smooth, fbm_noise(512, 1.0, 6))[0, 1]) < 0.3


def test_hash_is_the_documented_pcg():
    # reference values of the RXS-M-XS PCG hash (computed by hand from its definition)
    def pcg_ref(x):
        state = (x * 747796405 + 2891336453) & 0xFFFFFFFF
        word = (((state >> ((state >> 28) + 4)) ^ state) * 277803737) & 0xFFFFFFFF
        return ((word >> 22) ^ word) & 0xFFFFFFFF
    xs = [0, 1, 2, 12345, 0xFFFFFFFF, 2**31]
    assert pcg(np.array(xs, np.uint64)).tolist() == [pcg_ref(x) for x in xs]
    u = hash_uniform(3, np.arange(1, 1000), 0)
    assert 0 < u.min() and u.max() < 1 and abs(u.mean() - 0.5) < 0.03


def test_spectrum_amplitudes_fall_as_f_to_minus_beta_over_2():
    amp, phase = spectrum(4096, 2.0, 1)
    f = np.arange(1, 2049)
    gauss = amp * f  # undo 1/f^(β/2) with β = 2
    assert abs(gauss.mean()) < 0.1 and gauss.std() == pytest.approx(1.0, abs=0.1)
    assert phase.min() >= 0 and phase.max() < 2 * np.pi


def test_resample_eq_3_and_periodic_catmull_rom():
    sig = fbm_noise(64, 2.0, 9)
    t = np.arange(64, dtype=float)
    np.testing.assert_allclose(resample(sig, 1.0, 0.0, t), sig, atol=1e-12)       # interpolates samples
    np.testing.assert_allclose(resample(sig, 1.0, 64.0, t), sig, atol=1e-12)      # period n
    np.testing.assert_allclose(resample(sig, 2.0, 3.0, t[:10]), sig[(2 * t[:10].astype(int) + 3) % 64], atol=1e-12)
    x = np.linspace(-5, 70, 500)
    h = 1e-6
    value, slope = sample_periodic(sig, x)
    fd = (sample_periodic(sig, x + h)[0] - sample_periodic(sig, x - h)[0]) / (2 * h)
    np.testing.assert_allclose(slope, fd, atol=1e-5)  # C¹: derivative is exact and continuous
    left = sample_periodic(sig, np.arange(64) - 1e-9)[1]
    right = sample_periodic(sig, np.arange(64) + 1e-9)[1]
    np.testing.assert_allclose(left, right, atol=1e-6)


@pytest.mark.parametrize("n, beta", [(0, 1.0), (7, 1.0), (4096, 1.0), (64, 0.0), (64, -1.0), (64, np.nan)])
def test_invalid_arguments(n, beta):
    with pytest.raises(ValueError):
        fbm_noise(n, beta, 0)
    with pytest.raises(ValueError, match="backend"):
        fbm_noise(64, 1.0, 0, backend="cuda")


@pytest.mark.gl
def test_gpu_signal_equals_cpu(gl):
    for n, beta, seed in [(256, 1.0, 0), (256, 2.0, 8), (1024, 1.3, 77), (2048, 3.0, 2**31 + 11), (64, 0.7, 5)]:
        cpu = fbm_noise(n, beta, seed)
        gpu = fbm_noise(n, beta, seed, backend="gpu")
        assert gpu.dtype == np.float32
        assert np.abs(gpu - cpu).max() <= 1e-4 * cpu.std(), (n, beta, seed)


@pytest.mark.gl
def test_ripple_pass_is_batched_and_recomputes_only_changed_rows(gl):
    from leafview.deform.fbm import RIPPLE_SAMPLES
    from leafview.gpu.ripple import RipplePass

    rp = RipplePass(gl.ctx)
    try:
        keys = [(s, 1.0 + 0.1 * s) for s in range(40)]
        assert rp.update(keys) == 40 and rp.dispatches == 1          # 40 signals, one dispatch
        assert rp.update(keys) == 0 and rp.dispatches == 1           # nothing changed: no work
        keys[7] = (7, 2.5)
        assert rp.update(keys) == 1 and rp.dispatches == 2           # only the changed row
        for row in (0, 7, 39):
            seed, beta = keys[row]
            np.testing.assert_allclose(rp.read(row), fbm_noise(RIPPLE_SAMPLES, beta, seed), atol=1e-4)
    finally:
        rp.release()
    assert gl.ctx.error == "GL_NO_ERROR"
