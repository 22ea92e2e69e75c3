"""The frame worker of the localizer node: a thread that takes the newest filed frame.

The executor thread files each image with :meth:`FrameWorker.put` (a one-slot
:class:`~landmark_localizer.node_support.Mailbox`: a newer frame replaces one not yet
taken), the worker thread takes the newest and runs ``process`` on it; what ``process``
raises goes to ``on_error``, never ends the thread. :meth:`FrameWorker.close` wakes the
thread for good and waits for the frame in progress, so that nothing is processed or
published after a lifecycle deactivation. Between frames, at most every 2 s, and once
when frames stop, it hands the heap's free pages back to the system
(:mod:`~landmark_localizer.heap`), so that a relocalization's temporaries do not stay
resident. Pure Python, no rclpy.
"""
from __future__ import annotations

from collections.abc import Callable
import threading
from typing import Any

from landmark_localizer.heap import HeapTrimmer
from landmark_localizer.node_support import Mailbox

__all__ = ['WORKER_JOIN_S', 'FrameWorker']

#: How long :meth:`FrameWorker.close` waits for the frame being processed.
WORKER_JOIN_S = 5.0


class FrameWorker:
    """Runs ``process`` on the newest filed item, one at a time, in a thread of its own.

    Args:
        process: Called with each item taken.
        on_error: Called with what ``process`` raised.
        name: The thread's name.
        trimmer: Its ``after_frame`` is called after each item and its ``when_idle`` when
            none came for its ``period`` (default: a :class:`.HeapTrimmer`, 2 s).
    """

    def __init__(self, process: Callable[[Any], None],
                 on_error: Callable[[Exception], None], name: str = 'localizer-frames',
                 trimmer: HeapTrimmer | None = None) -> None:
        self._process, self._on_error = process, on_error
        self.trimmer = HeapTrimmer() if trimmer is None else trimmer
        self._mailbox = Mailbox()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def put(self, item: Any) -> bool:
        """File ``item``; return whether it replaced one not yet taken (a dropped frame)."""
        replaced, _ = self._mailbox.put(item)
        return replaced

    def close(self, timeout: float = WORKER_JOIN_S) -> None:
        """Stop taking items and wait (at most ``timeout``) for the one in progress."""
        self._mailbox.close()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout=timeout)

    @property
    def alive(self) -> bool:
        """Whether the thread still runs."""
        return self._thread.is_alive()

    def _run(self) -> None:
        while True:
            ok, item = self._mailbox.take(timeout=self.trimmer.period)
            if not ok:
                if self._mailbox.closed:
                    return
                self.trimmer.when_idle()   # no frame for a period
                continue
            try:
                self._process(item)
            except Exception as error:  # noqa: BLE001 - a node reports, it does not die
                self._on_error(error)
            self.trimmer.after_frame()
