"""The job state machine: states, the transition table, and the typed error for an illegal move.

    queued -> running -> succeeded | failed | canceled
    queued -> canceled | failed          (canceled before it ran; its scene vanished before it ran)
    failed | canceled -> queued          (retry: the job resumes from its checkpointed tiles)

The database applies a transition atomically (``UPDATE ... WHERE state IN sources(to)``), so two actors racing
(the dispatcher finishing a job while a user cancels it) cannot both win.
"""
from __future__ import annotations

from schemas import JobState

QUEUED, RUNNING, SUCCEEDED, FAILED, CANCELED = (JobState.queued, JobState.running, JobState.succeeded,
                                                JobState.failed, JobState.canceled)

TRANSITIONS: dict[JobState, frozenset[JobState]] = {
    QUEUED: frozenset({RUNNING, CANCELED, FAILED}),
    RUNNING: frozenset({SUCCEEDED, FAILED, CANCELED}),
    SUCCEEDED: frozenset(),
    FAILED: frozenset({QUEUED}),
    CANCELED: frozenset({QUEUED}),
}

TERMINAL = frozenset({SUCCEEDED, FAILED, CANCELED})  # nothing runs; only a retry moves failed/canceled on
ACTIVE = frozenset({QUEUED, RUNNING})


class IllegalTransition(Exception):
    """A job cannot move from its current state to the requested one."""

    def __init__(self, job_id: str, current: JobState, target: JobState):
        super().__init__(f"job {job_id} cannot go from {current.value} to {target.value}")
        self.job_id = job_id
        self.current = current
        self.target = target


def can_move(current: JobState, target: JobState) -> bool:
    return target in TRANSITIONS[current]


def sources(target: JobState) -> frozenset[JobState]:
    """The states from which ``target`` may be entered."""
    return frozenset(s for s, targets in TRANSITIONS.items() if target in targets)


def check(job_id: str, current: JobState, target: JobState) -> None:
    if not can_move(current, target):
        raise IllegalTransition(job_id, current, target)
