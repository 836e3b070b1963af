"""Prime's Shm medium from Python: topics read in place in shared memory, as
numpy views with no copy, topics published, services called.

    import prime
    d = prime.shm.Domain("robot")               # a participant, listed by `prime ls`
    odom = d.subscribe("sensors/odom")
    with odom.read(timeout=1.0) as s:          # prime.Timeout if nothing comes
        print(s.value["x"], s.stamp, s.sequence)

A described type (PRIME_DESCRIBE) arrives as a read-only 0-d numpy structured
array over the sample's bytes where the publisher wrote them; a raw topic as
a read-only memoryview. The sample stays held in the topic's ring (counted
in the topic's max_held) until the Sample is released (the end of its
`with` block, or release()) and no array or memoryview made from it lives.
"""

import atexit as _atexit
import re as _re
import sys as _sys
import weakref as _weakref

import numpy as _np

import prime as _prime
from prime._prime import Core as _Core
from prime._prime import Type as _RawType


class Sample:
    """One sample: .value (a numpy view or a memoryview), .stamp (seconds of
    the steady clock C++'s prime::Clock reads), .sequence."""

    def __init__(self, held, dtype, topic):
        self._held, self._dtype, self._topic = held, dtype, topic
        self.stamp, self.sequence = held.stamp, held.sequence

    @property
    def value(self):
        if self._held is None:
            raise ValueError(f"a sample of topic '{self._topic}' used after its release")
        if self._dtype is None:
            return memoryview(self._held)
        if self._held.size != self._dtype.itemsize:
            raise _prime.Damaged("damaged", f"a sample of topic '{self._topic}' has {self._held.size} bytes, "
                                            f"its type {self._dtype.itemsize}")
        return _np.frombuffer(self._held, dtype=self._dtype, count=1).reshape(())

    def release(self):
        """Gives the sample back (once no array made from it lives)."""
        self._held = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()
        return False


def _topic(core, name):
    """Topic `name`'s name, type and dtype (None: raw bytes; an undescribed
    type: its bytes, V<size>)."""
    info = core.topic(name)
    if info is None:
        raise _prime.NotFound("not found", f"no topic '{name}' in shm domain '{core.domain}'")
    return name, info["type"], _dtype(info["raw"], info["schema"], info["size"])


def _dtype(raw, schema, size):
    return None if raw else (_prime.dtype_of(schema, size) or _np.dtype(f"V{size}"))


class Subscriber:
    """A real subscriber of a topic (a `block` publisher waits for it)."""

    def __init__(self, core, name, history, spin, made=None, dtype=None):
        self._reader = core.subscribe(name, history, spin) if made is None else made
        self.name, self.type, self.dtype = _topic(core, name)
        if dtype is not None:
            self.dtype = dtype  # the type's own, as its maker wrote it (the same layout as the description's)

    def read(self, timeout=None):
        """The next sample; waits up to `timeout` seconds (None: until one
        comes, or Ctrl-C). Raises prime.Timeout."""
        return Sample(self._reader.read(timeout), self.dtype, self.name)

    def read_batch(self, max=64, timeout=None):
        """The samples there are, up to `max`, taken at once once one is
        (waiting up to `timeout` seconds for it: prime.Timeout), each held
        as read()'s is: at most what the topic's max_held leaves."""
        return [Sample(held, self.dtype, self.name) for held in self._reader.read_batch(max, timeout)]

    def try_read(self):
        """The next sample if one is there, else None."""
        held = self._reader.try_read()
        return None if held is None else Sample(held, self.dtype, self.name)

    def __iter__(self):
        while True:
            yield self.read()

    @property
    def lost(self):
        return self._reader.lost


class Publisher:
    """The publisher of a topic (its type is the topic's)."""

    def __init__(self, core, name, publisher=None, dtype=None):
        self.name, self.type, self.dtype = _topic(core, name)
        self._publisher = core.publisher(name) if publisher is None else publisher
        if dtype is not None:
            self.dtype = dtype  # the type's own, as its maker wrote it (the same layout as the description's)

    def message(self):
        """A zeroed message of the topic's type, to fill and publish."""
        if self.dtype is None:
            raise _prime.InvalidArgument("invalid argument", f"topic '{self.name}' carries raw bytes: publish bytes")
        return _np.zeros((), dtype=self.dtype)

    def publish(self, value, stamp=None):
        """Publishes `value` (copied once into shared memory): a numpy array
        of the topic's dtype, a dict of its fields, or bytes for a raw
        topic. `stamp`: seconds of the steady clock (default: now)."""
        self._publisher.publish(_message_bytes(value, self.dtype, f"topic '{self.name}' ({self.type})"), stamp)

    def loan(self, size=None):
        """A message loaned in shared memory, to write in place and publish
        (see Loan). `size`: the bytes of a raw topic's message."""
        if self.dtype is not None and size is not None:
            raise _prime.InvalidArgument("invalid argument", f"topic '{self.name}' carries {self.type}: its size "
                                                             "is the type's")
        if self.dtype is None and size is None:
            raise _prime.InvalidArgument("invalid argument", f"topic '{self.name}' carries raw bytes: give a size")
        loaned = self._publisher.loan(self.dtype.itemsize if size is None else size)
        return Loan(loaned, self.dtype, f"topic '{self.name}'")


class Loan:
    """A message loaned in the topic's ring in shared memory, written in
    place, and published at the end of its `with` block (not published if
    the block raises):

        with pub.loan() as msg:
            msg["x"] = 1.0
            msg["image"]["data"][:n] = pixels   # no copy but this one

    `msg[field]` reads and writes a field; `msg.value` is the whole message
    (a writable 0-d numpy array; raw topics: a uint8 array). A described
    type's message starts zeroed. Every array made from the loan must be gone
    when it is published: one still alive could write into a sample other
    processes read, so the loan is not published and prime.InUse raised
    (its place goes back to the ring once the last such array is gone).
    After its block, `msg` refuses use."""

    def __init__(self, loan, dtype, where):
        self._loan, self._where = loan, where
        # numpy holds one export of the loan's bytes, and with it one
        # reference to `loan`, until the last array made from them is gone.
        flat = _np.frombuffer(loan, dtype=_np.uint8)
        if dtype is not None:
            flat[:] = 0
            self._value = flat.view(dtype).reshape(())
        else:
            self._value = flat

    @property
    def value(self):
        if self._value is None:
            raise ValueError(f"a loan of {self._where} used after its end")
        return self._value

    def __getitem__(self, key):
        return self.value[key]

    def __setitem__(self, key, item):
        self.value[key] = item

    def publish(self, stamp=None):
        """Publishes the message (`stamp`: seconds of the steady clock; default now)."""
        loan = self._end()
        if loan is None:
            raise _prime.InUse("in use", f"an array made from the loan of {self._where} is still alive (del "
                                         "it before the loan ends): it could write into a published sample, "
                                         "so the loan was not published")
        loan.publish(stamp)

    def _end(self):
        """Ends this object's use of the loan: the loan itself if no export of
        its bytes is left, else None (it goes back to the ring with the last
        one)."""
        self.value  # noqa: B018  (refuses a loan already ended)
        self._value = None
        loan, self._loan = self._loan, None
        # Its references now: `loan` here and getrefcount's argument, and one
        # more while numpy's export of its bytes lives.
        return loan if _sys.getrefcount(loan) == 2 else None

    def __enter__(self):
        return self

    def __exit__(self, error, *rest):
        if self._value is None:
            return False
        if error is not None:
            self._end()  # not published: back to the ring with its last array
            return False
        self.publish()
        return False


class Domain:
    """A participant of the shared-memory domain `name`, listed by `prime ls`
    under `participant` (default: the program's name). Services it serves
    and syncs of its subscribers run until close() (or the end of its
    `with` block, its being let go, or the program's exit)."""

    def __init__(self, name, participant=""):
        self._core = _Core(name, participant)
        self._clients = {}
        self.name = name

    def subscribe(self, topic, history=0, spin=50e-6, type=None, capacity=64, block=False, max_message_size=None,
                  max_subscribers=8):
        """A subscriber of `topic`, reading from now (and up to `history`
        samples already there), spinning `spin` seconds before it sleeps.
        With no `type`, the topic must exist (prime.NotFound) and its type is
        its own. With a `type` (a prime.Type, or `bytes`), the topic is made
        with the QoS given if no one has made it yet (as publisher() makes
        it); else it must carry that type (prime.TypeMismatch) and have that
        QoS (prime.QosMismatch)."""
        if type is None:
            return Subscriber(self._core, topic, history, spin)
        made = self._core.subscribe(topic, history, spin, _raw_type(type, "a topic's type"), capacity, block,
                                    max_message_size or 0, max_subscribers)
        return Subscriber(self._core, topic, history, spin, made, _dtype_of(type))

    def publisher(self, topic, type=None, capacity=64, block=False, block_timeout=1.0, max_message_size=None,
                  max_subscribers=8):
        """The publisher of `topic`. With no `type`, the topic must exist and
        its type is its own. With a `type` (a prime.Type, or `bytes` for raw
        bytes up to `max_message_size`), the topic is created with the QoS
        given (as C++'s TopicQos: `block` is Overflow::block) if no one has
        opened it yet; else it must carry that type (prime.TypeMismatch)."""
        if type is None:
            return Publisher(self._core, topic)
        made = self._core.publisher(topic, _raw_type(type, "a topic's type"), capacity, block, block_timeout,
                                    max_message_size or 0, max_subscribers)
        return Publisher(self._core, topic, made, _dtype_of(type))

    def serve(self, service, fn, request, reply, workers=1, timeout=1.0, max_request_size=None, max_reply_size=None):
        """Serves `service` by `fn(request) -> reply` on `workers` threads of
        this process, to callers in any process of the domain, C++ or Python.
        `request` and `reply` are prime.Type (fn takes a read-only numpy
        value and returns an array or dict of the reply's fields) or `bytes`
        (fn takes bytes and returns bytes-like; then give the max sizes).
        A prime.Error raised by fn reaches the caller with its code; any
        other exception as prime.BlockFailed, named. `timeout` is how long
        a caller waits when it names no timeout of its own. Each call holds
        the GIL while fn runs; requests are copied once out of shared memory
        and replies once into it. prime.InUse if a live server serves it."""
        raw_request, raw_reply = _raw_type(request, "a request type"), _raw_type(reply, "a reply type")
        request_way = _Way(_dtype_of(request), service, "request", _described(request))
        reply_way = _Way(_dtype_of(reply), service, "reply", _described(reply))

        def handle(data):
            return reply_way.bytes_of(fn(request_way.value_of(data)))

        self._core.serve(service, raw_request, raw_reply, handle, workers, timeout, max_request_size or 0,
                         max_reply_size or 0)
        _serving.add(self)

    def close(self):
        """Stops its services and syncs (waiting for calls in progress;
        prime.InvalidArgument from inside one of its services' functions,
        which closing would wait for). Its subscribers and publishers stay
        usable."""
        _serving.discard(self)
        self._core.stop()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def call(self, service, request, timeout=None):
        """Calls `service` with `request` (a numpy array or dict of its request
        type, or bytes for raw) and returns its reply (a numpy array of its
        reply type, or bytes), waiting up to `timeout` seconds (None: the
        service's own; on the main thread Ctrl-C gives the call up, as
        KeyboardInterrupt): prime.Timeout, prime.NotFound, prime.PeerDead,
        prime.BlockFailed... as in C++."""
        key = (service, timeout)
        if key not in self._clients:
            info = self._core.service(service)
            if info is None:
                raise _prime.NotFound("not found", f"no service '{service}' in shm domain '{self.name}'")
            ways = [_Way(_dtype(info[w + "_raw"], info[w + "_schema"], _size_of(info[w + "_type"])), service, w,
                         info[w + "_type"]) for w in ("request", "reply")]
            self._clients[key] = (self._core.client(service, timeout), *ways)
        client, request_type, reply_type = self._clients[key]
        return reply_type.value_of(client.call(request_type.bytes_of(request)))


# Domains that serve: stopped at the program's exit, while their workers can
# still take the GIL to finish a call.
_serving = _weakref.WeakSet()


@_atexit.register
def _stop_serving():
    for domain in list(_serving):
        try:
            domain.close()
        except _prime.InvalidArgument:
            pass  # in a forked child: the parent's domain, for the parent to stop


def _raw_type(type, what):
    if type is bytes:
        return _RawType.raw()
    if isinstance(type, _prime.Type):
        return type._raw
    raise _prime.InvalidArgument("invalid argument", f"{what} is a prime.Type or bytes, not {type!r}")


def _dtype_of(type):
    return None if type is bytes else type.dtype


def _described(type):
    return "raw bytes" if type is bytes else type.described


class _Way:
    """One way of a service: bytes to and from its type (dtype None: raw)."""

    def __init__(self, dtype, service, way, type_name):
        self.dtype, self.service, self.way, self.type = dtype, service, way, type_name

    def bytes_of(self, value):
        return _message_bytes(value, self.dtype, f"service '{self.service}' ({self.type} {self.way})")

    def value_of(self, data):
        if self.dtype is None:
            return data
        if len(data) != self.dtype.itemsize:
            raise _prime.Damaged("damaged", f"service '{self.service}' answered {len(data)} bytes for its "
                                            f"{self.dtype.itemsize}-byte {self.type}")
        return _np.frombuffer(data, dtype=self.dtype, count=1).reshape(())


def _message_bytes(value, dtype, where):
    """`value` as the bytes of one message of `dtype` (None: raw bytes): a
    numpy array of that dtype, or a dict of its fields. `where` names the
    topic or service in the error."""
    if dtype is None:
        return memoryview(value).cast("B")
    if isinstance(value, dict):
        message = _np.zeros((), dtype=dtype)
        for field, v in value.items():
            if field not in dtype.names:
                raise _prime.TypeMismatch("type mismatch", f"{where} has no field '{field}'; it has "
                                                           f"{', '.join(dtype.names)}")
            try:
                message[field] = v
            except (ValueError, TypeError) as e:
                raise _prime.TypeMismatch("type mismatch", f"{where}: field '{field}' ({dtype[field]}) cannot "
                                                           f"take {v!r}: {e}") from None
        value = message
    value = _np.asarray(value)
    if value.size != 1 or not _prime.schema.same_layout(value.dtype, dtype):
        raise _prime.TypeMismatch("type mismatch", f"{where} takes one message of dtype {dtype}, not "
                                                   f"{value.size} of dtype {value.dtype}")
    return _np.ascontiguousarray(value).reshape(-1).view(_np.uint8)


def _size_of(type_name):
    # Fingerprint::describe(): "<name> (<size> bytes, align ..., layout ...)"
    found = _re.search(r"\((\d+) bytes", type_name)
    if not found:
        raise _prime.Damaged("damaged", f"a type described as {type_name!r} names no size")
    return int(found.group(1))
