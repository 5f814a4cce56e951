"""Reading ahead: the next frames decoded on a reader thread while the device fuses this one.

A drive's host work (a PNG decoded, per-azimuth poses; a polar scan's levels become power on
the device, ``stages.levels``) and the device's fusion of the frame before are independent, so
a reader thread makes them overlap:
``prefetched(read, n)`` yields ``read(0)``, ``read(1)``, ... in order, with at most ``depth``
of them read ahead of the one in hand (memory stays ``depth`` frames, whatever the drive's
length; a frame is read only once there is room for it, so it waits no longer than it must).
ISA-L's inflate (or PIL's decoding) and numpy's whole-array steps release the GIL, and so does waiting for the device,
which is why a thread (not a process, whose frames would be pickled across) is enough.

An exception in the reader (a corrupt scan's ``FrameFormatError``) is raised in the consumer
at the frame it belongs to, the same exception with its own sentence, after every frame
before it has been yielded; the consumer leaving early (an error of its own, Ctrl-C) stops
the reader and joins it, so no thread outlives the drive.
"""

import queue
import threading

# Frames read ahead: the next one decoded while the device fuses this one. A scan decodes several
# times faster than it fuses, so one is enough to keep the device busy; more would only add to
# each frame's latency (from its reading to its fusion) and to memory.
DEFAULT_DEPTH = 1


class _Failed:
    """The reader's exception, carried through the queue to the consumer."""

    def __init__(self, exc):
        self.exc = exc


_DONE = object()


def prefetched(read, n, depth=DEFAULT_DEPTH, overlap=None):
    """Yield ``read(j)`` for j in 0 .. n-1, in order, read on a thread at most ``depth`` items
    ahead of the one the consumer holds (``depth`` 0: read inline, no thread). ``read``'s
    exception for item j is raised here when item j is due. ``overlap(j)`` False holds item j's
    reading back until the consumer is back from item j - ``depth`` (with ``depth`` 1: done with
    the item before it), as if it were read inline: a bench times reading and consuming apart
    that way, in the same run as the overlap."""
    if depth <= 0:
        for j in range(n):
            yield read(j)
        return
    items = queue.Queue()
    ahead = threading.Semaphore(depth)         # taken before a read, given back when the consumer takes an item
    stop = threading.Event()

    def reader():
        try:
            for j in range(n):
                while not ahead.acquire(timeout=0.1):      # a bounded wait, so a consumer that left is noticed
                    if stop.is_set():
                        return
                if stop.is_set():
                    return
                items.put(read(j))
        except BaseException as exc:            # noqa: BLE001 - re-raised in the consumer
            items.put(_Failed(exc))
            return
        items.put(_DONE)

    thread = threading.Thread(target=reader, name="radarcl-reader", daemon=True)
    thread.start()
    try:
        for j in range(n + 1):
            item = items.get()
            if item is _DONE:
                return
            if isinstance(item, _Failed):
                raise item.exc
            if overlap is None or j + depth >= n or overlap(j + depth):      # past the last: nothing to hold back
                ahead.release()                  # the next read starts while the consumer works on this one
                yield item
            else:
                yield item
                ahead.release()                  # the consumer is back: done with this one
    finally:
        stop.set()
        thread.join()
