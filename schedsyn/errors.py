"""The small exception hierarchy of schedsyn.

Every error a user can cause derives from :class:`SchedsynError`; the CLI turns it into
a one-line message and exit code 2. Input problems also derive from ``ValueError`` so
that generic callers can catch them the usual way.
"""

from __future__ import annotations


class SchedsynError(Exception):
    """Base class of every error schedsyn raises on purpose."""


class ParameterError(SchedsynError, ValueError):
    """A model parameter, limit or setting is out of its allowed range."""


class StepTableError(SchedsynError, ValueError):
    """A chamber step table (CSV) is malformed or breaks a limit."""


class LogFormatError(SchedsynError, ValueError):
    """A measured log is malformed (missing column, NaN, time not increasing, ...)."""


class InfeasiblePlanError(SchedsynError):
    """No programme meets the request; the message says which requirement and by how much.

    ``best_plan``: when a plan was made but does not meet the requirement (a complete plan
    was required), that plan (:class:`schedsyn.planner.Plan`), else None.
    """

    def __init__(
        self, message: str, best_coverage: float | None = None, best_plan: object | None = None
    ):
        super().__init__(message)
        self.best_coverage = best_coverage
        self.best_plan = best_plan

    def __reduce__(self):  # keep best_coverage and best_plan across process boundaries
        return (type(self), (str(self), self.best_coverage, self.best_plan))


class SolverFailedError(SchedsynError):
    """A numerical solver failed for a reason other than infeasibility."""


class EnvironmentFaultError(SchedsynError):
    """The environment failed, not the input: an output cannot be written (permissions,
    disk full), a worker process was killed. The command line exits with code 3."""
