"""When collect() starts episodes and how many control steps a call takes.

Pure numpy on episode lengths: which episodes the first ``n`` transitions need
(:class:`Episodes`), a Kaplan-Meier estimate of how long episodes last from
the ended ones and the running ones' ages (:func:`kaplan_meier`,
:func:`expected_remaining`), and from it how many episodes to start
(:func:`episodes_to_start`) and how many steps the next call takes
(:func:`call_length`). The schedule decides how episodes are stepped, never
which transitions the first ``n`` are: with random actions the data depend on
the seed alone.
"""

from __future__ import annotations

import numpy as np

DEFAULT_PARALLEL = 256  # most episodes collect() steps together with a policy
_MOST_PARALLEL = 2048  # ... and with random actions, for the largest collections
_TRANSITIONS_PER_SLOT = 64  # random actions: a parallel episode per this many transitions asked for
_MIN_LIVE = 8  # fewest, while more may be needed (a constant: results must not depend on threads)
MOST_STEPS = 64  # most control steps collect() takes in one call


class Episodes:
    """Lengths of started episodes, which ones the first n transitions still need, and
    how many ended after each number of steps."""

    def __init__(self, n: int, ended_before: np.ndarray | None = None):
        self.n = n
        self.lengths = np.zeros(64, np.int64)
        self.count = 0
        # ended[k]: episodes that ended after k steps (the schedule's survival data;
        # a histogram, since sorting every ended length each pass cost as much as the step),
        # from ``ended_before`` on: those of earlier collections of the same episodes.
        self.ended = np.zeros(64, np.int64) if ended_before is None else ended_before.copy()

    def start(self, k: int) -> np.ndarray:
        """The numbers of ``k`` new episodes."""
        while self.count + k > len(self.lengths):
            self.lengths = np.concatenate([self.lengths, np.zeros_like(self.lengths)])
        self.count += k
        return np.arange(self.count - k, self.count)

    def end(self, episodes: np.ndarray) -> None:
        if len(episodes) == 0:
            return
        counts = np.bincount(self.lengths[episodes], minlength=len(self.ended))
        if len(counts) > len(self.ended):
            self.ended = np.concatenate([self.ended, np.zeros(len(counts) - len(self.ended), np.int64)])
        self.ended += counts

    def total(self) -> int:
        return int(self.lengths[: self.count].sum())

    def covered(self, episodes: np.ndarray) -> np.ndarray:
        """True where episodes 0..e already hold n transitions, so e need not go on.

        Lengths only grow, so once true it stays true, and the first n
        transitions in episode order never need a step beyond it.
        """
        return np.cumsum(self.lengths[: self.count])[episodes] >= self.n


def kaplan_meier(ended: np.ndarray, ages: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Kaplan-Meier estimate of P(length > t) at each of ``times`` (increasing step
    counts that include every length in ``ended`` up to the last of them).

    ``ended``, ``ages``: as :func:`expected_remaining` takes them. At t, the episodes
    at risk are those that ended after t steps or more and those running at age t or more.
    """
    inside = times < len(ended)
    at = np.minimum(times, len(ended) - 1)
    deaths = np.where(inside, ended[at], 0)
    ended_since = np.cumsum(ended[::-1])[::-1]  # episodes that ended after t steps or more
    at_risk = np.where(inside, ended_since[at], 0) + (len(ages) - np.searchsorted(np.sort(ages), times, side="left"))
    return np.cumprod(1.0 - deaths / np.maximum(at_risk, 1.0))


def expected_remaining(ended: np.ndarray, ages: np.ndarray, limit: float) -> tuple[float, np.ndarray]:
    """(expected length of a new episode, expected further steps of each running one).

    ``ended[k]``: how many episodes ended after k steps; ``ages``: steps taken so
    far by the running ones (censored lengths). The survival curve is the Kaplan-Meier
    estimate; the mean of the ended lengths alone runs short, since the short
    episodes end first.
    Beyond the longest length seen, survivors are assumed to go on to twice it
    (capped by the limit). Before any episode ends: the limit, or 100 steps.
    """
    steps = np.flatnonzero(ended)
    if len(steps) == 0:
        cap = limit if np.isfinite(limit) else 100.0
        return cap, np.maximum(cap - ages, 1.0)
    survival = np.concatenate([[1.0], kaplan_meier(ended, ages, steps)])  # on [edges[i], edges[i+1])
    ages = ages.astype(np.float64)
    longest = float(max(steps[-1], ages.max() if len(ages) else 0.0))
    tail_end = max(min(2.0 * longest, limit), longest)
    edges = np.concatenate([[0.0], steps, [tail_end]])
    area = np.concatenate([[0.0], np.cumsum(survival * np.diff(edges))])  # integral of S up to edges[i]
    k = np.searchsorted(edges, ages, side="right") - 1
    area_to_age = area[k] + survival[k] * (ages - edges[k])
    residual = (area[-1] - area_to_age) / np.maximum(survival[k], 1e-12)
    return float(area[-1]), np.maximum(residual, 1.0)


def default_parallel(n: int, random_actions: bool) -> int:
    """collect()'s default ``n_parallel`` for ``n`` transitions (a speed choice).

    With random actions the data do not depend on it, and more simulations a
    call spread the Python around each call over more steps, so that calls can
    be shorter and fewer steps idle after an episode's end. Too many for ``n``
    start a burst of episodes that ends in a long tail, hence about one per 64
    transitions. With a policy the controls' noise follows the lockstep order,
    so its default stays fixed.
    """
    if not random_actions:
        return DEFAULT_PARALLEL
    return int(min(max(n // _TRANSITIONS_PER_SLOT, DEFAULT_PARALLEL), _MOST_PARALLEL))


def call_length(ended: np.ndarray, ages: np.ndarray, caps: np.ndarray, call_cost: float, most: int) -> int:
    """Control steps for the next call: the most useful steps per cost (a speed choice only).

    ``ended``, ``ages``: as :func:`expected_remaining` takes them; ``caps``: steps
    after which each live episode is over or not needed. A call of K steps costs
    K steps of every live simulation plus ``call_cost`` (the Python around it, in
    simulation steps); it is useful for the steps each episode takes before it
    ends, which a Kaplan-Meier survival S estimates: an episode of age a takes
    the call's step j + 1 with probability S(a + j) / S(a). No call reaches
    further than the longest length seen, so the first ones, before any episode
    ends, stay short.
    """
    m = len(ages)
    seen = np.flatnonzero(ended)
    most = int(min(most, max(1, seen[-1] if len(seen) else 0, ages.max()), caps.max()))
    survival = kaplan_meier(ended, ages, np.arange(int(ages.max()) + most + 1))  # S(t) = P(length > t)
    area = np.concatenate([[0.0], np.cumsum(survival)])  # sum of S(u) for u < t
    # Episodes of the same age and cap count alike: a few dozen kinds among up to 2,048.
    kinds, counts = np.unique(ages * (most + 1) + np.minimum(caps, most).astype(np.int64), return_counts=True)
    age, cap = np.divmod(kinds, most + 1)
    k = np.arange(1, most + 1)
    steps = np.minimum(k[:, None], cap[None, :])
    useful = ((area[age + steps] - area[age]) / survival[age]) @ counts
    return int(np.argmax(useful / (k * m + call_cost))) + 1


def steps_to_cover(ep: np.ndarray, episodes: Episodes, n: int) -> np.ndarray:
    """Steps after which each live episode in ``ep`` covers the first ``n`` transitions.

    Episode e is covered once the lengths of episodes 0..e add up to n; each
    step lengthens every live one among them by one.
    """
    live = np.zeros(episodes.count, np.int64)
    live[ep] = 1
    behind = np.cumsum(episodes.lengths[: episodes.count])[ep]
    return -((behind - n) // np.cumsum(live)[ep])


def episodes_to_start(n_free: int, total: int, n: int, ended: np.ndarray, running: np.ndarray, limit: int) -> int:
    """How many new episodes ``collect`` starts now (at most ``n_free``).

    ``ended``, ``running``: as :func:`expected_remaining` takes them.

    Start an episode only when the live ones are not expected to supply the
    transitions still missing: starting all slots at once would cut long
    (time-limited) episodes short and throw most of them away. The schedule
    depends on episode lengths only, so it is deterministic. With a policy it
    fixes the lockstep order, which the controls' noise follows; with random
    actions the data do not depend on it. Lengths are estimated with the running
    episodes' ages as censored observations (:func:`expected_remaining`). A few
    episodes run at least while transitions are missing, so that the threads
    have work at once; none start once n are recorded.
    """
    if n_free == 0 or total >= n:
        return 0
    expected, remaining = expected_remaining(ended, running, limit)
    supply_now = total + remaining.sum()
    if supply_now >= n and len(running) >= _MIN_LIVE:  # the usual answer, cheaply
        return 0
    # Starting k more: supply after k additions of ``expected`` (added one at a time,
    # as cumsum does) and k more live; the first k at which both suffice.
    supply = np.cumsum(np.concatenate([[supply_now], np.full(n_free, expected)]))
    enough = (supply >= n) & (len(running) + np.arange(n_free + 1) >= _MIN_LIVE)
    return int(np.argmax(enough)) if enough.any() else n_free
