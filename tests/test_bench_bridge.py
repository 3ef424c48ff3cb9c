"""The Rerun bridge bench's memory verdict (ellipsled/bench/bridge.py memory_verdict): the last
entry's RSS level against the one before it, checked against series whose trend is known by
construction: a warm-up, the allocator's sawtooth, noise, with and without a leak."""
import numpy as np

from ellipsled.bench import bridge

E = bridge.FULL_ENTRY_STEPS


def series(leak_per_10k, seed=0, saw_MB=4.0, saw_steps=15_000, noise_MB=0.5, warm=(10_000, 28.0)):
    """RSS [MB] every RSS_SAMPLE_STEPS over ENTRIES entries: a ramp to ``warm[1]`` MB by step
    ``warm[0]``, then a sawtooth of ``saw_MB`` over ``saw_steps`` (its phase drawn), plus
    ``leak_per_10k`` MB per 10,000 steps and uniform noise."""
    rng = np.random.default_rng(seed)
    phase = rng.uniform(0, saw_steps)
    out = [(0, 100.0)]
    for i in range(bridge.RSS_SAMPLE_STEPS, bridge.ENTRIES * E + 1, bridge.RSS_SAMPLE_STEPS):
        v = 100.0 + warm[1] * min(i / warm[0], 1.0) + leak_per_10k * i / 10_000
        if i > warm[0]:
            v += saw_MB * (((i + phase) % saw_steps) / saw_steps)
        out.append((i, v + rng.uniform(-noise_MB, noise_MB)))
    return out


def test_a_leak_of_twice_the_bound_fails_and_a_sawtooth_without_one_passes_whatever_its_phase():
    lim = bridge.MEM_FLAT_MB_PER_10K_STEPS
    for seed in range(30):
        leak = bridge.memory_verdict(series(2.0 * lim, seed))
        flat = bridge.memory_verdict(series(0.0, seed))
        assert leak["memory_flat"] is False and abs(leak["rss_slope_MB_per_10k_steps"] - 2.0 * lim) < 0.6, seed
        assert flat["memory_flat"] is True and abs(flat["rss_slope_MB_per_10k_steps"]) < 0.6, seed


def test_the_levels_are_each_entrys_p90_and_the_growth_the_last_two_entries():
    rss = series(0.0, seed=5)
    v = bridge.memory_verdict(rss)
    a = np.array(rss)
    p90 = [np.percentile(a[(a[:, 0] > j * E) & (a[:, 0] <= (j + 1) * E), 1], 90) for j in range(3)]
    assert np.allclose(v["rss_level_MB_by_entry"], np.round(np.array(p90) - 100.0, 2))
    assert abs(v["rss_growth_last_entry_MB"] - (p90[2] - p90[1])) < 1e-9
    assert abs(v["rss_slope_MB_per_10k_steps"] - (p90[2] - p90[1]) / E * 1e4) < 1e-9
    assert abs(v["rss_growth_MB"] - (rss[-1][1] - 100.0)) < 1e-9
    one = bridge.memory_verdict([p for p in rss if p[0] <= E])       # one entry: nothing to compare
    assert one["memory_flat"] is None and one["rss_slope_MB_per_10k_steps"] is None
