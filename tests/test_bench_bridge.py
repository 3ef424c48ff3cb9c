"""The Rerun bridge bench's memory verdict (ellipsled/bench/bridge.py memory_verdict): a
least-squares slope over the second half's samples, checked against series whose trend is
known by construction."""
import numpy as np

from ellipsled.bench import bridge


def series(slope_per_10k, noise_MB, n=22_500, every=bridge.RSS_SAMPLE_STEPS, seed=0, warm=(7_500, 20.0)):
    """RSS growth [MB] at every ``every`` steps: a warm-up ramp to ``warm[1]`` MB by step
    ``warm[0]``, then ``slope_per_10k`` MB per 10,000 steps, plus uniform noise."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(0, n + 1, every):
        base = warm[1] * min(i / warm[0], 1.0) + slope_per_10k * max(i - warm[0], 0) / 10_000
        out.append((i, base + (rng.uniform(-noise_MB, noise_MB) if i else 0.0)))
    return out


def test_a_leak_above_the_bound_fails_through_the_noise_and_a_saturated_run_passes():
    lim = bridge.MEM_FLAT_MB_PER_10K_STEPS
    for seed in range(20):
        leak = bridge.memory_verdict(series(2.0 * lim, 1.5, seed=seed))    # +-1.5 MB: the noisier run's residuals
        flat = bridge.memory_verdict(series(0.0, 1.5, seed=seed))
        assert not leak["memory_flat"] and abs(leak["rss_slope_second_half_MB_per_10k_steps"] - 2.0 * lim) < 1.0
        assert flat["memory_flat"] and abs(flat["rss_slope_second_half_MB_per_10k_steps"]) < 1.0


def test_the_slope_is_the_fit_of_the_second_half_not_its_two_ends():
    """A series whose two ends sit on a dip: the difference of its middle and last samples
    reads a leak, the fit of the second half (numpy's polyfit as the oracle) does not."""
    rss = [(0, 0.0), (2500, 10.11), (5000, 17.19), (7500, 23.15), (10000, 23.34), (11250, 21.91), (12500, 23.84),
           (15000, 24.48), (17500, 19.85), (20000, 23.45), (22500, 23.91)]
    v = bridge.memory_verdict(rss)
    assert abs(v["rss_growth_second_half_MB"] - 2.0) < 1e-9 and v["rss_growth_MB"] == 23.91
    assert 2.0 / 11_250 * 10_000 > bridge.MEM_FLAT_MB_PER_10K_STEPS        # the two ends: 1.78 MB per 10k
    half = np.array(rss[5:])
    assert abs(v["rss_slope_second_half_MB_per_10k_steps"] - np.polyfit(half[:, 0], half[:, 1], 1)[0] * 1e4) < 1e-9
    assert v["memory_flat"] and 0.3 < v["rss_slope_second_half_MB_per_10k_steps"] < 0.5
