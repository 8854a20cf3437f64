"""Ctrl-C and SIGTERM as KeyboardInterrupt, never in the middle of a file a later step trusts.

The command line installs :func:`handler` for SIGINT and SIGTERM (:func:`install`; for
SIGINT too, because a process started from a non-interactive shell inherits SIGINT ignored).
Outside a :func:`critical` section the handler raises KeyboardInterrupt at once (the loop
then writes its checkpoint and the run ends with status ``interrupted``, exit 130). Inside
one — the writing of a checkpoint, of the final fields, of the summary — it only notes the
signal, and KeyboardInterrupt is raised when the section ends: the file is whole, then the
run stops.

A KeyboardInterrupt raised while Python runs a finalizer or a weak reference's callback (the
garbage collector may run one at any moment: during the set-up of an AMG hierarchy, say) is
printed as "Exception ignored in ..." and dropped; the program goes on as if no signal had
come. The handler therefore also notes each signal it raises for, and the time loop asks
:func:`check` before each step: a dropped one is raised there (and :func:`install` keeps
Python from printing it: the interruption's one line stays the only one).
"""

from __future__ import annotations

import signal
import sys
from contextlib import contextmanager

_depth = 0
_pending: int | None = None
_raised: int | None = None  # a signal raised as KeyboardInterrupt, not yet handled


def handler(signum, frame) -> None:
    global _pending, _raised
    if _depth:
        _pending = signum
        return
    _raised = signum
    raise KeyboardInterrupt


def check() -> None:
    """Raise KeyboardInterrupt for a signal whose exception Python dropped (it came while a
    finalizer ran); nothing otherwise."""
    global _raised
    if _raised is not None:
        _raised = None
        raise KeyboardInterrupt


def handled() -> None:
    """Where a KeyboardInterrupt is caught: the signal behind it, if any, was delivered."""
    global _raised
    _raised = None


def install() -> None:
    """SIGINT and SIGTERM → :func:`handler` (in the main thread of the command line), and
    :func:`unraisable` as Python's hook for the exceptions it drops."""
    signal.signal(signal.SIGTERM, handler)
    signal.signal(signal.SIGINT, handler)
    sys.unraisablehook = unraisable


def unraisable(info) -> None:
    """Python's report of an exception it dropped, but for a KeyboardInterrupt: that one is
    raised again by :func:`check`, and its traceback would only add lines to stderr."""
    if not issubclass(info.exc_type, KeyboardInterrupt):
        sys.__unraisablehook__(info)


def pending() -> bool:
    """True while a signal that arrived in a critical section waits to be raised."""
    return _pending is not None


@contextmanager
def critical():
    """A section a signal does not cut short (nestable); a signal that arrived meanwhile is
    raised as KeyboardInterrupt when the outermost section ends without an error."""
    global _depth, _pending
    _depth += 1
    try:
        yield
    except BaseException:
        _depth -= 1
        raise
    _depth -= 1
    if _depth == 0 and _pending is not None:
        _pending = None
        raise KeyboardInterrupt
