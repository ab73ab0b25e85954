"""Job kinds and states: shared by the job store (:mod:`service.jobs`), the schemas and the pipeline,
so none of them imports another for an enum."""
from __future__ import annotations

from enum import Enum


class JobState(str, Enum):
    """Life cycle of a job: queued -> running -> succeeded | failed | cancelled."""

    queued = "queued"
    running = "running"
    succeeded = "succeeded"
    failed = "failed"
    cancelled = "cancelled"

    @property
    def finished(self) -> bool:
        return self in (JobState.succeeded, JobState.failed, JobState.cancelled)


class JobKind(str, Enum):
    """What a job computes."""

    simulation = "simulation"
    diagnose = "diagnose"
    explain = "explain"
    compensation = "compensation"
    placement_search = "placement_search"
    circle = "circle"
