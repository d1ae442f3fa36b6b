import numpy as np
import pytest

from analysis.stats import permutation_p, policy_interval


def test_the_interval_holds_the_estimate_and_widens_with_the_spread_between_policies():
    rng = np.random.default_rng(1)
    alike = [rng.normal(0.5, 0.05, 64) for _ in range(4)]
    apart = [rng.normal(centre, 0.05, 64) for centre in (0.2, 0.4, 0.6, 0.8)]
    est, low, high = policy_interval(alike)
    assert low <= est <= high and high - low < 0.05
    est2, low2, high2 = policy_interval(apart)
    assert est2 == pytest.approx(0.5, abs=0.02)
    assert high2 - low2 > 5 * (high - low)  # policies, not robots, are the unit


def test_one_policy_gets_the_interval_of_its_robots_and_a_share_statistic_works():
    robots = np.array([0.0] * 90 + [1.0] * 10)
    est, low, high = policy_interval([robots])
    assert est == pytest.approx(0.1) and 0.03 < low < 0.1 < high < 0.17
    with pytest.raises(ValueError, match="at least one robot"):
        policy_interval([robots, np.array([])])


def test_permutation_p_is_exact_for_few_policies():
    assert permutation_p([0.1, 0.2, 0.3], [0.7, 0.8, 0.9]) == pytest.approx(1 / 20)  # 3 vs 3: never below 0.05
    assert permutation_p([0.1, 0.2, 0.3, 0.4], [0.7, 0.8, 0.9, 1.0]) == pytest.approx(1 / 70)
    assert permutation_p([0.7, 0.8, 0.9], [0.1, 0.2, 0.3]) == 1.0  # the claim goes the other way
    assert permutation_p([0.1, 0.2, 0.3], [0.7, 0.8, 0.9], alternative="two-sided") == pytest.approx(2 / 20)


def test_permutation_p_of_alike_configurations_is_large_and_random_relabellings_agree_with_exact_ones():
    rng = np.random.default_rng(2)
    a, b = rng.normal(0, 1, 8), rng.normal(0, 1, 8)
    assert permutation_p(a, b, alternative="two-sided") > 0.05
    a, b = rng.normal(0, 1, 12), rng.normal(1.5, 1, 12)  # C(24, 12) > the exact limit: random relabellings
    assert permutation_p(a, b) < 0.01
