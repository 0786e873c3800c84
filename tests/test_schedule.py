"""The episode schedule's contract (pure numpy): every requested transition is covered,
episodes are needed in order, and the estimates it runs on are Kaplan-Meier's."""

from __future__ import annotations

import numpy as np
import pytest

from tatl_mj.sampling import schedule


def run_schedule(true_lengths: np.ndarray, n: int, slots: int, limit: float) -> schedule.Episodes:
    """A collection of episodes of ``true_lengths`` steps, one step a pass, as collect() runs it."""
    episodes = schedule.Episodes(n)
    slot_episode = np.full(slots, -1, np.int64)
    for _ in range(10 * n + 100):  # a stalled schedule fails below
        free = np.flatnonzero(slot_episode < 0)
        running = episodes.lengths[slot_episode[slot_episode >= 0]]
        k = schedule.episodes_to_start(len(free), episodes.total(), n, episodes.ended, running, limit)
        assert 0 <= k <= len(free)
        assert k == 0 or episodes.total() < n  # none start once n are recorded
        slot_episode[free[:k]] = episodes.start(k)
        live = np.flatnonzero(slot_episode >= 0)
        if len(live) == 0:
            return episodes
        ep = slot_episode[live]
        episodes.lengths[ep] += 1
        ended = episodes.lengths[ep] >= true_lengths[ep]
        episodes.end(ep[ended])
        slot_episode[live[ended | episodes.covered(ep)]] = -1
    raise AssertionError("the schedule stalled")


@pytest.mark.parametrize(
    "lengths,limit",
    [
        (np.full(5000, 10), 10.0),  # every episode alike
        (np.random.default_rng(1).geometric(1 / 30, 5000), np.inf),  # falls, no time limit
        (np.minimum(np.random.default_rng(2).geometric(1 / 80, 5000), 200), 200.0),  # cut by a limit
        (np.r_[np.full(10, 400), np.ones(5000, np.int64)], 400.0),  # long ones first, then one-step
    ],
)
@pytest.mark.parametrize("n,slots", [(1, 4), (700, 8), (3000, 256)])
def test_every_requested_transition_is_covered_by_whole_episodes_in_order(lengths, limit, n, slots):
    episodes = run_schedule(lengths, n, slots, limit)
    taken = episodes.lengths[: episodes.count]
    covering = int(np.argmax(np.cumsum(taken) >= n))  # the episode holding transition n
    assert np.cumsum(taken)[-1] >= n
    # Every episode before it ran to its end: the first n transitions nest whole episodes.
    np.testing.assert_array_equal(taken[:covering], lengths[:covering])
    assert np.all(taken <= lengths[: episodes.count])


def test_no_episodes_start_once_none_are_needed():
    ended = np.bincount([5, 9])
    assert schedule.episodes_to_start(0, 0, 10, ended, np.array([], np.int64), 50.0) == 0
    assert schedule.episodes_to_start(4, 10, 10, ended, np.array([1]), 50.0) == 0
    # With nothing running and transitions missing, some start (the threads have work).
    assert 0 < schedule.episodes_to_start(64, 0, 10, ended, np.array([], np.int64), 50.0) <= 64


@pytest.mark.parametrize("seed", range(20))
def test_call_lengths_stay_within_their_bounds(seed):
    # At least one step; never beyond ``most``, beyond every episode's cap, nor beyond
    # the longest length seen or the oldest live episode's age.
    rng = np.random.default_rng(seed)
    ended = np.bincount(rng.integers(1, 60, size=rng.integers(0, 40)), minlength=64)
    ages = rng.integers(0, 50, size=rng.integers(1, 30))
    caps = rng.integers(1, 80, size=len(ages)).astype(np.float64)
    most = int(rng.integers(1, 65))
    k = schedule.call_length(ended, ages, caps, float(rng.uniform(0, 100)), most)
    seen = np.flatnonzero(ended)
    longest = max(1, seen[-1] if len(seen) else 0, ages.max())
    assert 1 <= k <= min(most, caps.max(), longest)


def test_default_parallelism_grows_with_random_collections_only():
    sizes = [schedule.default_parallel(n, random_actions=True) for n in (1, 10**3, 10**4, 10**5, 10**6, 10**8)]
    assert sizes == sorted(sizes) and sizes[0] == schedule.DEFAULT_PARALLEL < sizes[-1]
    # With a policy the controls' noise follows the lockstep order: the default stays fixed.
    assert {schedule.default_parallel(n, random_actions=False) for n in (1, 10**8)} == {schedule.DEFAULT_PARALLEL}


def test_expected_lengths_count_running_episodes_as_censored():
    """Kaplan-Meier by hand: one episode ended at 90, seven still run at age 90. S = 7/8 on
    [90, 180) (survivors assumed to go on to twice the longest seen), so a new episode is
    expected to last 90 + 90 * 7/8 = 168.75 steps, and each survivor 90 more; the mean of
    the ended lengths alone would say 90. Ended lengths come as a histogram (how many
    ended after k steps)."""
    expected, remaining = schedule.expected_remaining(np.bincount([90]), np.full(7, 90), limit=100_000.0)
    assert expected == pytest.approx(168.75)
    np.testing.assert_allclose(remaining, 90.0)
    # Running ages come back in their own order; the limit caps the tail.
    expected, remaining = schedule.expected_remaining(np.bincount([10, 30]), np.array([20, 0]), limit=40.0)
    # S: 1 on [0, 10), 2/3 on [10, 30) (at risk at 10: ended 10, 30 and age 20), 0 from 30 on
    # (at risk at 30: the ended 30 alone); the tail [30, 40) adds nothing.
    assert expected == pytest.approx(10 + 20 * 2 / 3)
    np.testing.assert_allclose(remaining, [(20 * 2 / 3 - 10 * 2 / 3) / (2 / 3), 10 + 20 * 2 / 3])
    # Before any episode ends: the limit.
    assert schedule.expected_remaining(np.zeros(8, np.int64), np.array([3]), 50.0)[0] == 50.0


def test_steps_to_cover_counts_the_live_episodes_before_each():
    # Episodes of 5, 3 and 2 steps, the last two running: after j more steps
    # episode 1 holds 5 + 3 + j and episode 2 holds 5 + 3 + 2 + 2j transitions.
    episodes = schedule.Episodes(20)
    for length in (5, 3, 2):
        episodes.lengths[episodes.start(1)] = length
    np.testing.assert_array_equal(schedule.steps_to_cover(np.array([1, 2]), episodes, 20), [12, 5])
    np.testing.assert_array_equal(schedule.steps_to_cover(np.array([1, 2]), episodes, 21), [13, 6])


def test_calls_reach_to_the_episodes_ends_and_no_further():
    # Every ended episode was 10 steps long: a call is worth making until the live
    # episodes end at step 10, never past it, and never past what is needed (caps).
    ended = np.bincount(np.full(50, 10))
    length = schedule.call_length
    assert length(ended, np.zeros(20, np.int64), np.full(20, 100.0), 20.0, 64) == 10
    assert length(ended, np.full(20, 6), np.full(20, 100.0), 20.0, 64) == 4
    assert length(ended, np.zeros(20, np.int64), np.full(20, 3.0), 20.0, 64) == 3
    # Before any episode ends, no further than the oldest has gone (at least 1).
    assert length(np.zeros(64, np.int64), np.full(20, 2), np.full(20, 100.0), 20.0, 64) == 2
    assert length(np.zeros(64, np.int64), np.zeros(20, np.int64), np.full(20, 100.0), 20.0, 64) == 1
    # Half end at 2 steps and half at 40: long calls idle half the simulations, but
    # a call costing nothing extra is then worth one step at a time (no idling).
    mixed = np.bincount(np.r_[np.full(50, 2), np.full(50, 40)])
    assert length(mixed, np.ones(20, np.int64), np.full(20, 100.0), 0.0, 64) == 1
