"""Run a frame iterator on a background thread, a few items ahead of its consumer.

Decoding (``cv2.imdecode``, video demuxing) and preparation (resize,
undistortion) spend their time in OpenCV, which releases the GIL, so on two
cores they overlap with the tracker's flow and BA instead of adding to them.
Items come out in order; an exception in the producer is raised in the
consumer at the point where the item would have come; a consumer that stops
early (an error, ``break``) stops the producer.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Iterable, Iterator
from typing import TypeVar

T = TypeVar("T")

_DONE = object()


class _Failure:
    def __init__(self, exc: BaseException):
        self.exc = exc


def prefetched(items: Iterable[T], ahead: int = 4) -> Iterator[T]:
    """Yield ``items`` in order while a daemon thread produces up to ``ahead`` of them in advance."""
    if ahead <= 0:
        yield from items
        return
    box: queue.Queue = queue.Queue(maxsize=ahead)
    stop = threading.Event()

    def put(item) -> bool:
        while not stop.is_set():
            try:
                box.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def produce() -> None:
        try:
            for item in items:
                if not put(item):
                    return
            put(_DONE)
        except BaseException as exc:  # handed to the consumer
            put(_Failure(exc))

    worker = threading.Thread(target=produce, name="droidw-prefetch", daemon=True)
    worker.start()
    try:
        while True:
            item = box.get()
            if item is _DONE:
                return
            if isinstance(item, _Failure):
                raise item.exc
            yield item
    finally:
        stop.set()
        worker.join(timeout=5.0)
