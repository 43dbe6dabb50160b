"""The prefetch thread: order, errors, early stop."""

from __future__ import annotations

import threading
import time

import pytest

from droidw_cli.runtime.prefetch import prefetched


def test_items_come_out_in_order():
    assert list(prefetched(iter(range(100)), ahead=3)) == list(range(100))
    assert list(prefetched(iter(range(5)), ahead=0)) == list(range(5))


def test_a_producer_error_reaches_the_consumer_after_the_good_items():
    def items():
        yield 1
        yield 2
        raise ValueError("corrupt container")

    got = []
    with pytest.raises(ValueError, match="corrupt container"):
        for x in prefetched(items(), ahead=4):
            got.append(x)
    assert got == [1, 2]


def test_closing_early_stops_the_producer():
    produced = []

    def items():
        for k in range(10_000):
            produced.append(k)
            yield k

    gen = prefetched(items(), ahead=2)
    assert next(gen) == 0
    gen.close()
    n = len(produced)
    time.sleep(0.3)
    assert len(produced) == n <= 5  # nothing more after the close: at most `ahead` + in flight
    assert not any(t.name == "droidw-prefetch" and t.is_alive() for t in threading.enumerate())
