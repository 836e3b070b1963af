"""The prime Python package against C++ processes (tests/python/peer.cpp),
both ways: topics read in place and published, services called, and every
error as its prime exception. Run by CTest (tests/python/CMakeLists.txt),
which puts the built package on PYTHONPATH and names the peer and the tool."""

import itertools
import os
import select
import signal
import subprocess
import sys
import textwrap
import threading
import time

import numpy as np
import pytest

import prime

PEER = os.environ["PRIME_PY_PEER"]
# The peer's types as Python declares them (tests/python/peer.cpp).
COMMAND = prime.Type("robot::Command", [("value", "<i8"), ("gain", "<f8")])
POSE = prime.Type("robot::Pose", {"names": ["x", "y", "id", "frame", "v"],
                                  "formats": ["<f8", "<f8", "<i4", [("size", "<u4"), ("data", "S16")], ("<f4", (3,))],
                                  "offsets": [0, 8, 16, 20, 40], "itemsize": 56})
TOOL = os.environ.get("PRIME_TOOL")
_domains = itertools.count()


@pytest.fixture
def domain():
    return f"py-{os.getpid()}-{next(_domains)}"


class Peer:
    """A peer process; says its lines on stdout, stops when stdin closes."""

    def __init__(self, *args):
        self.process = subprocess.Popen([PEER, *map(str, args)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                        text=True)
        self.expect("ready")

    def expect(self, line, timeout=10):
        ready, _, _ = select.select([self.process.stdout], [], [], timeout)
        assert ready, f"the peer said nothing in {timeout} s (waiting for {line!r})"
        got = self.process.stdout.readline().strip()
        assert got == line, f"the peer said {got!r}, not {line!r}"

    def say(self, line):
        self.process.stdin.write(line + "\n")
        self.process.stdin.flush()

    def close(self, timeout=10):
        if self.process.stdin and not self.process.stdin.closed:
            self.process.stdin.close()
        return self.process.wait(timeout)

    def kill(self):
        self.process.kill()
        self.process.wait(10)


def shm_mappings():
    """The address ranges of this process's mappings of Prime's segments."""
    ranges = []
    with open("/proc/self/maps") as maps:
        for line in maps:
            fields = line.split()
            if len(fields) >= 6 and fields[5].startswith("/dev/shm/prime."):
                start, end = (int(x, 16) for x in fields[0].split("-"))
                ranges.append((start, end))
    return ranges


def test_described_samples_from_cpp_are_numpy_views_in_shared_memory(domain):
    peer = Peer("publish", domain, 5)
    d = prime.shm.Domain(domain, participant="pytest")
    poses = d.subscribe("pose")
    assert poses.dtype.names == ("x", "y", "id", "frame", "v")
    peer.say("go")
    peer.expect("done")
    kept = []
    for i in range(1, 6):
        with poses.read(timeout=5) as s:
            v = s.value
            assert v.shape == () and not v.flags.owndata
            assert (float(v["x"]), float(v["y"]), int(v["id"])) == (i / 2, -i, i)
            assert bytes(v["frame"]["data"])[: int(v["frame"]["size"])] == b"map"
            assert list(v["v"]) == [i, 2 * i, 3 * i]
            assert s.sequence == i - 1  # the topic's sequence, from 0
            address = v.ctypes.data
            assert any(start <= address < end for start, end in shm_mappings()), "read in place in /dev/shm"
            with pytest.raises(ValueError):
                v["x"] = 0.0  # read-only: the publisher's bytes
            kept.append(v)
        with pytest.raises(ValueError, match="after its release"):
            s.value
    # An array outlives its with block: its sample stays held, so it still reads the same.
    assert [int(v["id"]) for v in kept] == [1, 2, 3, 4, 5]
    with pytest.raises(prime.Timeout) as timeout:
        poses.read(timeout=0.05)
    assert timeout.value.code == "timeout"
    assert poses.try_read() is None
    assert peer.close() == 0


def test_python_publishes_to_a_cpp_subscriber(domain):
    peer = Peer("subscribe", domain, 4)
    d = prime.shm.Domain(domain)
    commands = d.publisher("command")
    commands.publish({"value": 1, "gain": 0.25})
    message = commands.message()
    message["value"], message["gain"] = 2, 0.5
    commands.publish(message)
    with commands.loan() as loaned:  # written in place in the ring, published at the end of the block
        assert any(start <= loaned.value.ctypes.data < end for start, end in shm_mappings())
        loaned["value"], loaned["gain"] = 3, 0.75
    with pytest.raises(ValueError, match="after its end"):
        loaned["value"] = 0
    with pytest.raises(prime.InUse, match="still alive"):
        with commands.loan() as loaned:
            kept = loaned.value["value"]  # could write into a published sample: refused, nothing published
            loaned["value"] = 99
    with pytest.raises(RuntimeError):
        with commands.loan() as loaned:
            loaned["value"] = 98
            raise RuntimeError("the block failed: its loan is not published")
    with commands.loan() as loaned:
        loaned.value["value"] = 4
        loaned["gain"] = 1.0
        kept[...] = 97  # the refused loan's place, held while `kept` lives: never this one
    peer.expect("ok 4")
    del kept
    assert peer.close() == 0


def thread_state(native_id):
    """A thread's state as the kernel reports it ('R' running, 'S' asleep...)."""
    with open(f"/proc/self/task/{native_id}/stat") as stat:
        return stat.read().rsplit(")", 1)[1].split()[0]


def test_a_loan_let_go_does_not_wait_for_a_publish_waiting_for_room(domain):
    """A `block` publish waiting for room holds its publisher. A loan of that
    publisher let go meanwhile, on another thread, goes back without waiting
    for it (the wait ends with the reads, not with block_timeout), and the
    GIL stays free for the thread that reads."""
    d = prime.shm.Domain(domain)
    commands = d.subscribe("command", type=COMMAND, capacity=4, block=True)
    publisher = d.publisher("command", type=COMMAND, capacity=4, block=True, block_timeout=30.0)
    loaned = publisher.loan()  # one of the ring's four places
    for i in range(1, 4):
        publisher.publish({"value": i, "gain": 0.0})
    started, outcome = threading.Event(), []

    def publish_fourth():
        started.set()  # the GIL is let go next inside publish, which waits for room
        try:
            publisher.publish({"value": 4, "gain": 0.0})
            outcome.append("published")
        except prime.Error as error:
            outcome.append(error)

    waiter = threading.Thread(target=publish_fourth)
    waiter.start()
    started.wait()
    deadline = time.monotonic() + 10
    while thread_state(waiter.native_id) != "S":  # asleep on the topic's futex, the publisher's lock held
        assert time.monotonic() < deadline, "the fourth publish never waited for room"
        time.sleep(0.001)
    del loaned  # waited, with the GIL, for the publish's block_timeout before the fix
    late = d.subscribe("command", history=4)  # what is published so far
    assert [int(sample.value["value"]) for sample in iter(late.try_read, None)] == [1, 2, 3], \
        "the loan went back only once the publish had stopped waiting for room"
    # Room is made by reading: the waiting publish goes on and nothing is lost.
    assert [int(commands.read(timeout=5).value["value"]) for _ in range(4)] == [1, 2, 3, 4]
    waiter.join(10)
    assert outcome == ["published"] and commands.lost == 0
    with publisher.loan() as again:  # the place the dropped loan took is back
        again["value"] = 5
    assert int(commands.read(timeout=5).value["value"]) == 5


def test_a_wrong_type_is_refused_by_name(domain):
    peer = Peer("subscribe", domain, 1)
    d = prime.shm.Domain(domain)
    commands = d.publisher("command")
    with pytest.raises(prime.TypeMismatch, match="command"):
        commands.publish(np.zeros((), dtype=[("value", "<i4")]))
    with pytest.raises(prime.TypeMismatch, match="no field .speed."):
        commands.publish({"speed": 3})
    with pytest.raises(prime.TypeMismatch, match="one message"):
        commands.publish(np.zeros(3, dtype=commands.dtype))
    with pytest.raises(prime.NotFound, match="no topic 'nothing'"):
        d.subscribe("nothing")
    commands.publish({"value": 1, "gain": 0.25})  # nothing else was lost
    peer.expect("ok 1")
    peer.close()


def test_calls_to_a_cpp_service_and_its_errors(domain):
    peer = Peer("serve", domain)
    d = prime.shm.Domain(domain)
    reply = d.call("double", {"value": 21, "gain": 0.5}, timeout=5)
    assert (int(reply["value"]), float(reply["gain"])) == (42, 1.0)
    with pytest.raises(prime.BlockFailed, match="no motors") as failed:
        d.call("fail", {"value": 1, "gain": 1.0}, timeout=5)
    assert failed.value.code == "block failed"
    with pytest.raises(prime.NotFound):
        d.call("nobody", b"", timeout=1)
    with pytest.raises(prime.TypeMismatch):
        d.call("double", np.zeros(3), timeout=5)
    peer.kill()  # kill -9: a dead server is an error, not a hang
    with pytest.raises((prime.NotFound, prime.PeerDead)):
        d.call("double", {"value": 1, "gain": 1.0}, timeout=2)


@pytest.mark.skipif(TOOL is None, reason="the prime tool is not built")
def test_prime_ls_lists_the_python_participant(domain):
    peer = Peer("publish", domain, 1)
    d = prime.shm.Domain(domain, participant="planner-py")
    listing = subprocess.run([TOOL, "ls", "--domain", domain], capture_output=True, text=True, check=True).stdout
    rows = [line.split() for line in listing.splitlines()]
    assert ["planner-py", str(os.getpid()), "yes"] in [row[:3] for row in rows]
    del d
    peer.close()


def wait_until_asleep(task):
    """Waits until the thread /proc/<pid>[/task/<tid>] sleeps in the kernel's futex code (in read())."""
    deadline = time.monotonic() + 10
    while "futex" not in open(f"{task}/wchan").read():
        assert time.monotonic() < deadline, f"{task} never slept in read()"
        time.sleep(0.001)  # the poll's interval: what it waits for is the condition above


def test_ctrl_c_ends_a_blocking_read(domain):
    peer = Peer("publish", domain, 1)
    script = textwrap.dedent(f"""
        import prime
        d = prime.shm.Domain({domain!r})
        poses = d.subscribe("pose", spin=0)
        try:
            print("waiting", flush=True)
            poses.read()
        except KeyboardInterrupt:
            print("interrupted", flush=True)
    """)
    reader = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        assert reader.stdout.readline().strip() == "waiting"
        wait_until_asleep(f"/proc/{reader.pid}")  # its one thread
        reader.send_signal(signal.SIGINT)
        out, _ = reader.communicate(timeout=10)
        assert out.strip() == "interrupted" and reader.returncode == 0
    finally:
        reader.kill()
    peer.close()


def line_within(stream, seconds):
    """The next line of `stream`, which must come within `seconds`."""
    ready, _, _ = select.select([stream], [], [], seconds)
    assert ready, f"no line in {seconds} s"
    return stream.readline().strip()


def test_ctrl_c_gives_up_a_service_call_and_the_next_call_gets_its_own_answer(domain):
    entered, release = threading.Event(), threading.Event()

    def held(data):
        entered.set()
        release.wait(30)
        return data

    with prime.shm.Domain(domain) as d:
        d.serve("held", held, bytes, bytes, workers=2, max_request_size=16, max_reply_size=16)
        script = textwrap.dedent(f"""
            import prime
            d = prime.shm.Domain({domain!r})
            try:
                print("calling", flush=True)
                d.call("held", b"first", timeout=60)
            except KeyboardInterrupt:
                print("interrupted", flush=True)
            print(bytes(d.call("held", b"second", timeout=60)).decode(), flush=True)
        """)
        caller = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
        try:
            assert line_within(caller.stdout, 10) == "calling"
            assert entered.wait(10)  # the request is in a worker: the caller waits for its answer
            wait_until_asleep(f"/proc/{caller.pid}")
            caller.send_signal(signal.SIGINT)
            assert line_within(caller.stdout, 10) == "interrupted"  # not the call's 60 s, nor the worker's 30
            release.set()  # the first answer, given up, is dropped
            assert line_within(caller.stdout, 10) == "second"
            assert caller.wait(10) == 0
        finally:
            release.set()
            caller.kill()


def test_a_daemon_thread_asleep_in_read_lets_the_interpreter_exit(domain):
    # At exit Python ends such a thread as it takes the GIL back: through a
    # C++ destructor that was std::terminate (exit 134).
    peer = Peer("publish", domain, 1)
    script = textwrap.dedent(f"""
        import sys, threading, prime
        d = prime.shm.Domain({domain!r})
        poses = d.subscribe("pose", spin=0)
        reader = threading.Thread(target=poses.read, daemon=True)
        reader.start()
        print(reader.native_id, flush=True)
        sys.stdin.readline()  # exits once the test saw the reader asleep in read()
    """)
    child = subprocess.Popen([sys.executable, "-c", script], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    try:
        wait_until_asleep(f"/proc/{child.pid}/task/{child.stdout.readline().strip()}")
        out, err = child.communicate("exit\n", timeout=30)
        assert child.returncode == 0, err
    finally:
        child.kill()
    peer.close()


def test_schemas_make_dtypes_field_by_field():
    dtype = prime.dtype_of("{x@0:f64,n@8:vec4@0,8,4(i32),s@32:str7@0,4,a@44:arr2,8({p@0:u8,q@4:f32})}", 64)
    assert dtype.itemsize == 64 and dtype.names == ("x", "n", "s", "a")
    assert dtype.fields["n"][1] == 8 and dtype["n"]["data"].shape == (4,)
    assert dtype["a"].shape == (2,) and dtype["a"].base.itemsize == 8
    # A description is another process's bytes: what does not fit is prime.Damaged, never a crash.
    for hostile in ("{x@0:f65}", "{x@0:f64,y@8:f64}", "{a@0:f64,v@8:?2147483648}", "{a@0:f64,v@8:?4294967296}",
                    "{x@0:f64,x@0:f64}", "{x@0:arr1000000,8(f64)}", "{x0:f64}", "{x@0:f64", "{" * 5000,
                    "{x@0:vec2@0,8,4(i32)}", "{x@99999999999999999999:u8}", "{x@0:str8@0,4}x"):
        with pytest.raises(prime.Damaged):
            prime.dtype_of(hostile, 8)


def test_a_cpp_program_calls_services_served_from_python(domain):
    d = prime.shm.Domain(domain, participant="py-server")
    threads = []

    def triple(command):
        threads.append(threading.get_ident())
        assert not command.flags.writeable
        return {"value": int(command["value"]) * 3, "gain": float(command["gain"]) * 3}

    def refuse(command):
        raise prime.InvalidArgument("invalid argument", "gain out of range")

    d.serve("triple", triple, request=COMMAND, reply=COMMAND)
    d.serve("refuse", refuse, COMMAND, COMMAND)
    d.serve("raise", lambda command: 1 // 0, COMMAND, COMMAND)
    peer = Peer("call", domain, 50)  # typed in C++: it binds only if the fingerprints are equal
    peer.expect("ok 50")
    assert peer.close() == 0
    assert len(threads) == 50 and threading.get_ident() not in threads, "run on the service's worker"
    reply = d.call("triple", {"value": 2, "gain": 0.5}, timeout=5)  # and from Python
    assert (int(reply["value"]), float(reply["gain"])) == (6, 1.5)
    with pytest.raises(prime.InvalidArgument, match="gain out of range"):
        d.call("refuse", {"value": 1, "gain": 1.0}, timeout=5)
    with pytest.raises(prime.InUse):
        d.serve("triple", triple, COMMAND, COMMAND)
    d.close()
    with pytest.raises(prime.Error):  # no longer served: an error, not a hang
        d.call("triple", {"value": 1, "gain": 1.0}, timeout=0.5)


def test_raw_services_from_python_and_their_limits(domain):
    with prime.shm.Domain(domain) as d:
        d.serve("reverse", lambda data: data[::-1], bytes, bytes, max_request_size=64, max_reply_size=64)
        d.serve("big", lambda data: b"x" * 100, bytes, bytes, max_request_size=8, max_reply_size=16)
        d.serve("wrong", lambda command: np.zeros(3), COMMAND, COMMAND)
        d.serve("pairs", lambda command: {"value": 1, "speed": 2}, COMMAND, COMMAND, workers=2)
        assert d.call("reverse", b"abc", timeout=5) == b"cba"
        with pytest.raises(prime.TooLarge, match="100 bytes"):
            d.call("big", b"a", timeout=5)
        with pytest.raises(prime.TypeMismatch, match="one message"):
            d.call("wrong", {"value": 1, "gain": 1.0}, timeout=5)
        with pytest.raises(prime.TypeMismatch, match="no field 'speed'"):
            d.call("pairs", {"value": 1, "gain": 1.0}, timeout=5)
        assert d.call("reverse", b"served on", timeout=5) == b"no devres"  # after every failure
        with pytest.raises(prime.InvalidArgument, match="max_request_size"):
            d.serve("sizeless", lambda data: data, bytes, bytes)
        with pytest.raises(prime.InvalidArgument, match="prime.Type or bytes"):
            d.serve("typeless", lambda data: data, str, bytes)


def test_a_topic_made_in_python_is_read_by_cpp_and_python(domain):
    d = prime.shm.Domain(domain)
    commands = d.publisher("command", type=COMMAND)  # the peer's QoS: capacity 64
    peer = Peer("subscribe", domain, 3)  # opens it as robot::Command: the fingerprints are equal
    mine = d.subscribe("command")
    assert mine.dtype == COMMAND.dtype  # read back from the description Python wrote
    for i in range(1, 4):
        commands.publish({"value": i, "gain": i / 4})
    peer.expect("ok 3")
    assert peer.close() == 0
    assert [int(mine.read(timeout=5).value["value"]) for _ in range(3)] == [1, 2, 3]
    for other in (prime.Type("robot::Command", COMMAND.dtype, layout=2), prime.Type("robot::Order", COMMAND.dtype)):
        with pytest.raises(prime.TypeMismatch, match="robot::Command"):
            d.publisher("command", type=other)
    with pytest.raises(prime.InUse):
        d.publisher("command", type=COMMAND)  # its publisher lives
    raw = d.publisher("bytes", type=bytes, max_message_size=32)
    raw.publish(b"hello")
    assert bytes(d.subscribe("bytes", history=1).read(timeout=5).value) == b"hello"


def test_a_python_type_of_a_cpp_described_type_is_that_type(domain):
    peer = Peer("publish", domain, 1)
    d = prime.shm.Domain(domain)
    assert POSE.described == "robot::Pose (56 bytes, align 8, layout 1)"
    with pytest.raises(prime.InUse):  # the type is robot::Pose's: refused only because the peer publishes it
        d.publisher("pose", type=POSE)
    poses = d.subscribe("pose")
    assert poses.dtype["frame"]["data"] == POSE.dtype["frame"]["data"] and poses.dtype.itemsize == 56
    peer.close()


def test_types_are_checked_and_described_as_cpp_describes_them():
    assert prime.schema.same_layout(prime.dtype_of(POSE.schema, 56), POSE.dtype)
    assert not prime.schema.same_layout(prime.dtype_of(POSE.schema, 56), COMMAND.dtype)
    assert POSE.schema == "{x@0:f64,y@8:f64,id@16:i32,frame@20:{size@0:u32,data@4:arr16,1(char)},v@40:arr3,4(f32)}"
    assert prime.dtype_of(POSE.schema, 56)["frame"]["data"] == np.dtype("S16")
    assert COMMAND.alignment == 8 and prime.Type("a::B", [("c", "u1"), ("d", "u1")]).alignment == 1
    for name, dtype, kwargs, why in (("", "<f8", {}, "C\\+\\+ name"),
                                     ("a::B", [("x", "<f8"), ("c", "u1")], {}, "multiple of its alignment"),
                                     ("a::B", "<f8", {"alignment": 3}, "power of two"),
                                     ("a::B", [("o", "O")], {}, "cannot hold"),
                                     ("a::B", ">f8", {}, "cannot hold"),
                                     ("a::B", [("a b", "<f8")], {}, "named as C"),
                                     ("a::B", [("x", [])], {}, "one at least")):
        with pytest.raises(prime.InvalidArgument, match=why):
            prime.Type(name, dtype, **kwargs)


def test_batches_of_views_are_taken_at_once_and_held_each(domain):
    peer = Peer("publish", domain, 5)
    d = prime.shm.Domain(domain)
    poses = d.subscribe("pose")
    peer.say("go")
    peer.expect("done")
    first = poses.read_batch(max=3, timeout=5)
    assert [int(s.value["id"]) for s in first] == [1, 2, 3]
    rest = poses.read_batch(max=10, timeout=5)
    assert [int(s.value["id"]) for s in rest] == [4, 5]
    assert [s.sequence for s in first + rest] == [0, 1, 2, 3, 4]
    assert all(any(a <= s.value.ctypes.data < b for a, b in shm_mappings()) for s in first)
    with pytest.raises(prime.Timeout):
        poses.read_batch(max=4, timeout=0.05)
    with pytest.raises(prime.InvalidArgument):
        poses.read_batch(max=0)
    peer.close()


def test_sync_puts_cpp_samples_together_by_stamp(domain):
    peer = Peer("pair", domain, 8)
    d = prime.shm.Domain(domain)
    scan, odom = d.subscribe("scan"), d.subscribe("odom")
    exact = prime.sync(prime.exact_time(), d.subscribe("scan"), d.subscribe("odom"))
    pairs = prime.sync(prime.approximate_time(max_span=0.005), scan, odom)
    with pytest.raises(prime.InvalidArgument, match="given to a sync"):
        scan.read(timeout=0)
    with pytest.raises(prime.InvalidArgument, match="given to a sync"):
        prime.sync(prime.exact_time(), scan, d.subscribe("odom"))
    peer.say("next")  # pair 1
    for i in range(1, 8):
        peer.say("next")  # pair i + 1: set i is decided once it is there (in step: a slow reader sees the newest sets)
        with pairs.read(timeout=5) as pair:
            s, o = pair
            assert (int(s.value["id"]), int(o.value["value"])) == (i, i)
            assert pair.stamps[1] - pair.stamps[0] == pytest.approx(0.001, abs=1e-6)
            assert pair.skew == pytest.approx(0.001, abs=1e-6)
    peer.expect("done")
    with pytest.raises(prime.Timeout):
        exact.read(timeout=0.2)  # no two stamps are equal
    peer.close()


def test_a_sync_puts_eight_topics_together_as_cpp_can(domain):
    d = prime.shm.Domain(domain)
    cameras = [d.publisher(f"camera{i}", type=COMMAND) for i in range(9)]
    frames = [d.subscribe(f"camera{i}") for i in range(9)]
    with pytest.raises(prime.InvalidArgument, match="2 to 8 subscribers, not 9"):
        prime.sync(prime.exact_time(), *frames)
    sets = prime.sync(prime.exact_time(), *frames[:8])
    for stamp in (5.0, 6.0):  # in step: a reader slower than the sets sees the newest
        for i, camera in enumerate(cameras[:8]):
            camera.publish({"value": i, "gain": stamp}, stamp=stamp)
        with sets.read(timeout=5) as one:
            assert [int(s.value["value"]) for s in one] == list(range(8))
            assert one.stamps == pytest.approx([stamp] * 8) and one.skew == 0
    cameras[8].publish({"value": 8, "gain": 0.0})
    assert int(frames[8].read(timeout=5).value["value"]) == 8  # refused with the others: still its own


def test_sync_refuses_what_it_cannot_do(domain):
    peer = Peer("pair", domain, 0)
    d = prime.shm.Domain(domain)
    scan = d.subscribe("scan")
    with pytest.raises(prime.InvalidArgument, match="2 to 8"):
        prime.sync(prime.exact_time(), scan)
    with pytest.raises(prime.InvalidArgument, match="given twice"):
        prime.sync(prime.exact_time(), scan, scan)
    with pytest.raises(prime.InvalidArgument, match="policy"):
        prime.sync("exact", scan, d.subscribe("odom"))
    with pytest.raises(prime.InvalidArgument):
        prime.sync(prime.within_tolerance(-1.0), scan, d.subscribe("odom"))
    assert scan.try_read() is None  # after each refusal, still its own
    peer.close()


@pytest.mark.skipif(TOOL is None, reason="the prime tool is not built")
def test_handles_a_forked_child_inherits_are_its_parents(domain):
    # A child of fork() (multiprocessing's default) that used or freed them
    # would act on the parent's subscriber slot and lease.
    peer = Peer("publish", domain, 1)
    script = textwrap.dedent(f"""
        import gc, os, sys, prime
        d = prime.shm.Domain({domain!r}, participant="forker")
        poses = d.subscribe("pose")
        pid = os.fork()
        if pid == 0:
            for use in (lambda: poses.try_read(), lambda: d.subscribe("pose"), lambda: d.call("x", b"")):
                try:
                    use()
                    os._exit(3)
                except prime.InvalidArgument as e:
                    assert "forked" in str(e), e
            mine = prime.shm.Domain({domain!r}, participant="child")  # its own: usable
            assert mine.subscribe("pose").try_read() is None
            del poses, d, mine
            gc.collect()
            sys.exit(0)  # a full exit: the interpreter lets every handle go
        _, status = os.waitpid(pid, 0)
        print(os.waitstatus_to_exitcode(status), flush=True)
        sys.stdin.readline()
        with poses.read(timeout=5) as s:
            print(int(s.value["id"]), flush=True)
        sys.stdin.readline()
    """)
    parent = subprocess.Popen([sys.executable, "-c", script], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert parent.stdout.readline().strip() == "0", "the child refused the parent's handles and exited cleanly"
        listing = subprocess.run([TOOL, "ls", "--domain", domain], capture_output=True, text=True, check=True).stdout
        assert ["forker", str(parent.pid)] in [row.split()[:2] for row in listing.splitlines()], listing
        peer.say("go")
        parent.stdin.write("\n")
        parent.stdin.flush()
        assert parent.stdout.readline().strip() == "1", "the parent's subscriber still reads"
        parent.communicate("\n", timeout=10)
        assert parent.returncode == 0
    finally:
        parent.kill()
    peer.close()


def test_a_cpp_sync_puts_together_what_python_publishes(domain):
    d = prime.shm.Domain(domain)
    scans, odoms = d.publisher("scan", type=POSE), d.publisher("odom", type=COMMAND)  # Python's types, C++'s topics
    peer = Peer("sync", domain, 5)
    t0 = time.monotonic()  # prime::Clock's seconds
    for i in range(1, 6):
        stamp = t0 + i * 0.01
        scans.publish({"id": i, "frame": (2, b"py")}, stamp=stamp)
        odoms.publish({"value": i, "gain": 0.0}, stamp=stamp)
        peer.expect(f"set {i}")  # in step: a sync's reader that falls behind sees the newest sets
    assert peer.close() == 0


def test_data_laid_out_as_its_type_says_is_taken_whatever_numpy_calls_it(domain):
    # A padded nested struct, a 2-D array, fields out of offset order, bytes:
    # the description flattens them, the layout is the same.
    inner = np.dtype({"names": ["a"], "formats": ["<i4"], "offsets": [0], "itemsize": 8})
    layout = np.dtype({"names": ["cov", "tag", "inner", "n"], "formats": [("<f8", (2, 3)), "S3", inner, "<u2"],
                       "offsets": [0, 56, 48, 60], "itemsize": 64})
    Odd = prime.Type("test::Odd", layout)
    d = prime.shm.Domain(domain)
    odd = d.publisher("odd", type=Odd)
    reader = d.subscribe("odd")
    message = np.zeros((), dtype=Odd.dtype)
    message["cov"] = np.arange(6.0).reshape(2, 3)
    message["tag"], message["inner"]["a"], message["n"] = b"abc", 7, 9
    odd.publish(message)
    with reader.read(timeout=5) as s:
        v = s.value
        assert v.dtype.itemsize == 64 and bytes(v.tobytes()) == bytes(message.tobytes())
        assert list(np.asarray(v["cov"]).ravel()) == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0] and int(v["n"]) == 9
        odd.publish(v)  # what was read goes back out as it is: the parsed dtype is the same layout
    assert reader.read(timeout=5).value.tobytes() == message.tobytes()
    d.serve("same", lambda m: m, Odd, Odd)
    assert d.call("same", message, timeout=5).tobytes() == message.tobytes()
    with pytest.raises(prime.TypeMismatch):
        odd.publish(np.zeros((), dtype=COMMAND.dtype))
    d.close()


def test_a_sync_that_cannot_start_gives_nothing_away(domain):
    peer = Peer("pair", domain, 0)
    d = prime.shm.Domain(domain)
    scan, odom = d.subscribe("scan"), d.subscribe("odom")
    with pytest.raises(prime.InvalidArgument, match="depth"):
        prime.sync(prime.exact_time(depth=0), scan, odom)
    assert scan.try_read() is None and odom.try_read() is None  # still theirs
    prime.sync(prime.exact_time(), scan, odom)
    peer.close()


def test_a_serving_domain_let_go_or_closed_from_its_own_service(domain):
    peer = Peer("publish", domain, 1)
    script = textwrap.dedent(f"""
        import prime
        d = prime.shm.Domain({domain!r})
        Command = prime.Type("robot::Command", [("value", "<i8"), ("gain", "<f8")])
        def close_me(c):
            other = prime.shm.Domain({domain!r})
            other.close()  # another domain closes from here as anywhere
            del other
            try:
                d.close()
            except prime.InvalidArgument as e:
                return {{"value": 1 if "inside" in str(e) else 2, "gain": 0.0}}
            return {{"value": 3, "gain": 0.0}}
        d.serve("close-me", close_me, Command, Command)
        print(int(d.call("close-me", {{"value": 0, "gain": 0.0}}, timeout=5)["value"]), flush=True)
        d.serve("busy", lambda c: c, Command, Command)
        del d  # let go while serving, not closed: stopped without the GIL its workers need
        print("let go", flush=True)
    """)
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=30)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == ["1", "let", "go"]
    peer.close()


def test_a_subscriber_makes_its_topic_and_a_cpp_publisher_fills_it(domain):
    d = prime.shm.Domain(domain)
    poses = d.subscribe("pose", type=POSE)  # no one has made it: made here, with the peer's QoS
    with pytest.raises(prime.TypeMismatch):
        d.subscribe("pose", type=COMMAND)
    with pytest.raises(prime.QosMismatch):
        d.subscribe("pose", type=POSE, capacity=8)
    peer = Peer("publish", domain, 2)  # opens it as robot::Pose, capacity 64
    peer.say("go")
    peer.expect("done")
    assert [int(poses.read(timeout=5).value["id"]) for _ in range(2)] == [1, 2]
    peer.close()
