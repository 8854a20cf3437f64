"""The state a run ends in: one definition for the loop that sets it, the run folder that
records it (summary.json's ``status``), and the sweeps, plots and studies that read it.

A :class:`Status` is a ``str`` (``Status.STEADY == "steady"``; JSON and CSV write its
value), so folders written before it existed read the same.
"""

from __future__ import annotations

from enum import Enum


class Status(str, Enum):
    """How a run ended (``RunResult.status``, summary.json's ``status``)."""

    #: it ran the steps it was given (``--steps``)
    COMPLETED = "completed"
    #: the energy stopped changing (``--until-steady``)
    STEADY = "steady"
    #: not steady after ``--max-steps``
    MAX_STEPS = "max_steps"
    #: a step was not finite and could not be retried; the last finite state is saved
    DIVERGED = "diverged"
    #: stopped by a signal; its checkpoint resumes it
    INTERRUPTED = "interrupted"
    #: (a job) it could not run: an error, with its reason (``NAME.failed.json``)
    FAILED = "failed"
    #: (a job) its folder is held by another live process
    BUSY = "busy"
    #: (a sweep's point) nothing has run yet
    PENDING = "pending"
    #: (a sweep's point) its summary.json cannot be read as a run's
    DAMAGED = "damaged"
    #: (a sweep's point) not run: its start ended otherwise than it asks (``when``)
    SKIPPED = "skipped"

    __str__ = str.__str__
    __format__ = str.__format__


#: a run that will not go further when it is asked again: skipped, not resumed
ENDED = frozenset({Status.COMPLETED, Status.STEADY, Status.MAX_STEPS, Status.DIVERGED})
#: a run with a final state to analyse (its shape, its energy in a table or a plot)
HAS_RESULT = frozenset({Status.COMPLETED, Status.STEADY, Status.MAX_STEPS})
