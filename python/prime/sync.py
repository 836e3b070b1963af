"""Subscribers' samples put together by stamp, as C++'s prime::sync does it
(the same matchers, run by the domain's own threads):

    scan, odom = d.subscribe("sensors/scan"), d.subscribe("sensors/odom")
    pairs = prime.sync(prime.approximate_time(max_span=0.02), scan, odom)
    with pairs.read(timeout=1.0) as pair:     # a Synced: one Sample per subscriber
        s, o = pair
        print(s.value["ranges"], o.value["x"], pair.skew)

A subscriber given to a sync is read by the sync only (reading it directly
is prime.InvalidArgument).
"""

import prime as _prime
from prime import _prime as _ext
from prime.shm import Sample as _Sample


class Policy:
    """How a sync puts samples together (see the functions below)."""

    def __init__(self, kind, depth=32, tolerance=0.0, max_span=None, min_interval=(), age_penalty=0.0, trigger=0):
        self.kind, self.depth, self.tolerance, self.max_span = kind, depth, tolerance, max_span
        self.min_interval, self.age_penalty, self.trigger = list(min_interval), age_penalty, trigger

    def __repr__(self):
        return f"prime.Policy({self.kind!r})"


def exact_time(depth=32):
    """Samples whose stamps are equal; `depth` samples per input wait for a match."""
    return Policy("exact_time", depth)


def within_tolerance(tolerance, depth=32):
    """Samples whose stamps lie within `tolerance` seconds of each other, closest first."""
    return Policy("within_tolerance", depth, tolerance=tolerance)


def approximate_time(max_span=None, min_interval=(), age_penalty=0.0, depth=32):
    """The adaptive matcher of ROS's ApproximateTime: no tolerance needed;
    sets never wider than `max_span` seconds; `min_interval` (seconds, per
    input) lets a set be decided before the next samples come; see C++'s
    prime::ApproximateTime."""
    return Policy("approximate_time", depth, max_span=max_span, min_interval=min_interval, age_penalty=age_penalty)


def latest_of_each(trigger=0, depth=32):
    """On each sample of input `trigger` (None: of any input), with the newest of every other."""
    return Policy("latest_of_each", depth, trigger=-1 if trigger is None else trigger)


class Synced(tuple):
    """One set: a Sample per subscriber, in the order given, with .stamps
    (each one's) and .skew (the newest less the oldest, seconds). Its
    samples are released at the end of its `with` block."""

    @property
    def stamps(self):
        return [s.stamp for s in self]

    @property
    def skew(self):
        return max(self.stamps) - min(self.stamps)

    def release(self):
        for s in self:
            s.release()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()
        return False


class Sync:
    """A reader of a sync's sets."""

    def __init__(self, policy, subscribers):
        if not isinstance(policy, Policy):
            raise _prime.InvalidArgument("invalid argument", f"a sync's first argument is its policy, not {policy!r}")
        for s in subscribers:
            if not isinstance(s, _prime.shm.Subscriber):
                raise _prime.InvalidArgument("invalid argument", f"a sync takes subscribers, not {s!r}")
        self._subscribers = list(subscribers)
        self._sync = _ext.sync(policy.kind, policy.tolerance, policy.depth, policy.max_span, policy.min_interval,
                               policy.age_penalty, policy.trigger, [s._reader for s in subscribers])

    def read(self, timeout=None):
        """The next set; waits up to `timeout` seconds (None: until one comes,
        or Ctrl-C). Raises prime.Timeout."""
        held = self._sync.read(timeout)
        return Synced(_Sample(h, s.dtype, s.name) for h, s in zip(held, self._subscribers))

    def __iter__(self):
        while True:
            yield self.read()


def sync(policy, *subscribers):
    """A sync of 2 to 8 subscribers (prime.shm.Domain.subscribe) by `policy`."""
    return Sync(policy, subscribers)
