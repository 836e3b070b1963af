"""The Python end of prime_python_bench (python_bench.cpp): reads what the
C++ parent publishes on a raw topic, in place, through numpy.

    reader.py latency DOMAIN   each sample on "ping": answers on "pong" with its
                               sequence (its first 8 bytes) and when it was read
                               (CLOCK_MONOTONIC ns: C++'s steady_clock)
    reader.py stream DOMAIN    every sample on "stream", which must come in order with
                               none lost: answers on "pong" with the last sequence
                               every 256 samples, and 0 (or 1 once one was missing)
    reader.py serve DOMAIN     serves "echo" (raw bytes, up to 1 MiB) from Python: each
                               request comes back whole as its reply
"""

import sys
import threading
import time

import numpy as np

import prime

mode, domain = sys.argv[1], sys.argv[2]
d = prime.shm.Domain(domain, participant="bench-python")
if mode == "serve":
    d.serve("echo", lambda request: request, bytes, bytes, max_request_size=1 << 20, max_reply_size=1 << 20)
    print("ready", flush=True)
    threading.Event().wait()  # serves until the parent kills it
source = d.subscribe("ping" if mode == "latency" else "stream")
pong = d.publisher("pong")
answer = np.zeros(2, dtype="<u8")
print("ready", flush=True)
for n, sample in enumerate(source, 1):
    with sample:
        seq = int(np.frombuffer(sample.value, dtype="<u8", count=1)[0])  # read where the parent wrote it
    if mode == "latency":
        answer[0], answer[1] = seq, time.clock_gettime_ns(time.CLOCK_MONOTONIC)
        pong.publish(answer.view(np.uint8))
    else:
        if seq != n:
            answer[1] = 1  # lost or out of order: the parent fails the run
        if n % 256 == 0 or answer[1]:
            answer[0] = seq
            pong.publish(answer.view(np.uint8))
