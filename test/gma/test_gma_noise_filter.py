"""The modifier filter matched to the gradient noise (:class:`~kite_rto.gma.NoiseFilter`, gma/noise_filter.py):
the gain recursion itself, and on a noisy closed-form plant (test_gma_noise's) that it averages the noise better
than the fixed filter while it still follows the iterate when it moves."""
import numpy as np
import pytest

from kite_rto.gma import GMASettings, ModifierFilter, NoiseFilter, TrustRegion
from kite_rto.gma.noise_filter import noise_gain

from test_gma_noise import tail_stats


def test_at_one_point_the_gain_is_one_over_n():
    """Same point, same noise: K = 1, 1/2, 1/3, ... (the running mean), whatever the drift bound."""
    s = np.array([2.0, 5.0])
    for n in range(1, 7):
        K, P = noise_gain([np.zeros(2)] * n, [s] * n, drift=100.0, width=[1.0, 1.0])
        np.testing.assert_allclose(K, 1.0 / n)
        np.testing.assert_allclose(P, s ** 2 / n)


def test_long_steps_forget_and_exact_components_pass_through():
    s = np.array([1.0, 0.0])
    K, _ = noise_gain([np.zeros(2), np.ones(2)], [s, s], drift=1e6, width=[1.0, 1.0])
    np.testing.assert_allclose(K, [1.0, 1.0], atol=1e-9)      # a long step: the old estimate says nothing
    K, _ = noise_gain([np.zeros(2), np.full(2, 1e-3)], [s, s], drift=1.0, width=[1.0, 1.0])
    assert K[0] == pytest.approx(0.5, abs=1e-3) and K[1] == 1.0   # a tiny step: averaging; s = 0: taken as is
    # the drift is per box width: the same step in a box ten times wider drifts ten times less
    K_wide, _ = noise_gain([np.zeros(2), np.ones(2)], [s, s], drift=10.0, width=[10.0, 10.0])
    K_narrow, _ = noise_gain([np.zeros(2), np.ones(2)], [s, s], drift=10.0, width=[1.0, 1.0])
    assert K_wide[0] < K_narrow[0]


def test_the_noise_is_pooled_over_the_chain():
    """One estimate claiming a tiny standard error does not get a high gain: R is the chain's mean variance."""
    pts = [np.zeros(1)] * 3
    K, _ = noise_gain(pts, [np.array([3.0]), np.array([3.0]), np.array([0.01])], drift=0.0, width=[1.0])
    np.testing.assert_allclose(K, 1.0 / 3.0)                    # same point, pooled R: the running mean
    K, P = noise_gain(pts[:2], [np.array([3.0]), np.array([1.0])], drift=0.0, width=[1.0])
    np.testing.assert_allclose(P, 5.0 / 2)                      # R = (9 + 1) / 2, P = R / 2


def test_bad_input_names_the_values():
    with pytest.raises(ValueError, match="as many points"):
        noise_gain([np.zeros(2)], [], 1.0, [1.0, 1.0])
    with pytest.raises(ValueError, match=r"NoiseFilter.drift=-1.0: expected every value in \[0.0, inf\]"):
        NoiseFilter(drift=-1.0)


def test_noise_matched_filter_averages_more_than_the_fixed_one():
    """On the noisy closed-form plant: the recorded modifiers follow lambda_k = (1 - K) lambda_{k-1} + K measured
    with K from noise_gain over the chain; the iterates scatter less than with the fixed filter b = 0.5 and end
    at least as close to the plant optimum."""
    sigma, c_opt = 3e-3, np.array([2 / 3, 5 / 6])
    base = dict(filter_gain=0.7, trust_region=TrustRegion(radius=0.25, min_radius=1e-3))
    stats = {}
    for name, settings in (("fixed", GMASettings(modifier_filter=ModifierFilter(0.5), **base)),
                           ("noise", GMASettings(noise_filter=NoiseFilter(drift=0.5), **base))):
        spread, err = [], []
        for seed in range(3):
            tail, hist = tail_stats(settings, sigma, seed)
            its = hist.iterations
            if name == "noise":
                measured = np.array([r.grad_cost - r.grad_phi_hat for r in its])
                lam = np.array([r.lam for r in its])
                width = np.array([5.0, 5.0])
                for k in (1, 5, len(its) - 1):
                    K, _ = noise_gain([r.c_k for r in its[:k + 1]], [r.grad_cost_std for r in its[:k + 1]],
                                      0.5, width)
                    np.testing.assert_allclose(lam[k], (1 - K) * lam[k - 1] + K * measured[k], rtol=1e-9,
                                               atol=1e-12)
                assert "filtered by noise" in " ".join(its[-1].notes)
            spread.append(np.max(np.std(tail, axis=0)))
            err.append(np.max(np.abs(tail.mean(axis=0) - c_opt)))
        stats[name] = (np.mean(spread), np.mean(err))
    assert stats["noise"][0] < 0.7 * stats["fixed"][0], stats
    assert stats["noise"][1] <= 1.5 * stats["fixed"][1] + 1e-3, stats
