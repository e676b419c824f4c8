"""How a run ended: its end state, exit code and summary (paper sections 2 and 5); pure.

A run of a task net ends in one of :data:`END_STATES`; :data:`EXIT_CODES` gives the exit code of
``petrobot run`` (and ``demo``) for each, 0 only for a normal end. :class:`RunSummary` is what
:meth:`coordinator.runtime.Runtime.run` returns: the end state and why, the final marking, and the
results per primitive action.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from services.results import ActionResult

__all__ = ["ALL_CALLS_FAILED", "END_STATES", "EXIT_CODES", "ActionStats", "RunSummary"]

END_STATES: dict[str, str] = {
    "completed": "nothing more can happen and the marking is home (declared, else the initial marking; "
                 "control places and sink places such as counters aside) or meets the run's goal (--goal)",
    "stuck": "nothing more can happen and tokens are left away from home (in primitive-task places, or a "
             "resource not returned); the places are named",
    "waiting_for_operator": "only an operator command could move the run on, and no operator can send one "
                            "(standard input is not a terminal, --no-input) and --wait was not given",
    "aborted": "the operator aborted the run; running primitive actions were cancelled",
    "deadline": "--max-seconds ran out while the run was still going; running primitive actions were cancelled",
    "interrupted": "Ctrl-C (or the coordinator stopped); `petrobot run NET --resume` continues it",
}
"""Each end state and what it means."""

EXIT_CODES: dict[str, int] = {
    "completed": 0,
    "stuck": 1,
    "waiting_for_operator": 3,
    "deadline": 4,
    "aborted": 5,
    "interrupted": 130,
}
"""The exit code of each end state (2 is a run that could not start: bad net, services or journal)."""

ALL_CALLS_FAILED = 6
"""The exit code of a run that would end normally but in which every primitive-action call errored."""


@dataclass
class ActionStats:
    """Results of one primitive action in a run (durations in seconds)."""

    task: str
    action: str
    node: str
    calls: int = 0
    success: int = 0
    failure: int = 0
    error: int = 0
    wall_s: list[float] = field(default_factory=list)

    def record(self, result: ActionResult) -> None:
        """Count one result."""
        self.calls += 1
        setattr(self, result.status.value, getattr(self, result.status.value) + 1)
        self.wall_s.append(result.wall_s)

    @property
    def mean_wall_s(self) -> float:
        """Mean wall-clock duration on the node, seconds (0 when no call returned)."""
        return sum(self.wall_s) / len(self.wall_s) if self.wall_s else 0.0


@dataclass
class RunSummary:
    """How a run went.

    Attributes:
        run_id: the run.
        end_state: one of :data:`END_STATES`.
        final_marking: the marking at the end (places with tokens).
        firings: firings in the run (a resumed run counts those before the interruption too).
        duration_s: wall-clock time of this execution, seconds.
        actions: results per (primitive task, primitive action) (a resumed run counts those before
            the interruption too).
        errors: every error of the run, in words, in order (a call's reason, a refused subscription).
        note: why the run ended in its state, in words.
        detail: one line per stuck place, operator option or awaited event behind ``note``.
        reconciled: calls given up on (node trouble) whose node told their fate afterwards.
        differed: one line per reconciled call whose final status on its node is not the one the
            net went on with ("node beta finished slow with success after the coordinator declared
            it lost").
        unreconciled: one line per call given up on whose node could not be asked before the run
            ended (the journal keeps the coordinator's error for it).
    """

    run_id: str
    end_state: str
    final_marking: dict[str, int]
    firings: int
    duration_s: float
    actions: dict[tuple[str, str], ActionStats]
    errors: list[str]
    note: str = ""
    detail: tuple[str, ...] = ()
    reconciled: int = 0
    differed: tuple[str, ...] = ()
    unreconciled: tuple[str, ...] = ()

    @property
    def calls(self) -> int:
        """Primitive-action results received."""
        return sum(st.calls for st in self.actions.values())

    @property
    def all_calls_failed(self) -> bool:
        """At least one call returned and every one was an error."""
        return self.calls > 0 and all(st.error == st.calls for st in self.actions.values())

    @property
    def exit_code(self) -> int:
        """0 for a normal end; see :data:`EXIT_CODES` and :data:`ALL_CALLS_FAILED`."""
        code = EXIT_CODES.get(self.end_state, 1)
        if code == 0 and self.all_calls_failed:
            return ALL_CALLS_FAILED
        return code

    def format(self, *, max_errors: int = 5) -> str:
        """A human-readable multi-line summary: the end and why, the marking, the actions, the errors
        (the first ``max_errors``, then "and N more")."""
        lines = [f"run {self.run_id}: {self.end_state} after {self.firings} firings in {self.duration_s:.2f} s"]
        if self.note:
            lines.append(f"  {self.note}")
        lines.extend(f"  - {d}" for d in self.detail)
        if self.all_calls_failed and self.end_state == "completed":
            lines.append(f"  every one of the {self.calls} primitive-action calls ended in error")
        lines.append(f"final marking: {self.final_marking or '{}'}")
        if self.actions:
            rows = list(self.actions.values())
            wt = max(14, *(len(st.task) + 2 for st in rows))
            wa = max(22, *(len(st.action) + 2 for st in rows))
            wn = max(10, *(len(st.node) + 1 for st in rows))
            lines.append(f"{'task':<{wt}}{'action':<{wa}}{'node':<{wn}}{'calls':>6}{'ok':>5}{'fail':>5}{'err':>5}"
                         f"{'mean s':>9}")
            for st in rows:
                lines.append(f"{st.task:<{wt}}{st.action:<{wa}}{st.node:<{wn}}{st.calls:>6}{st.success:>5}"
                             f"{st.failure:>5}{st.error:>5}{st.mean_wall_s:>9.3f}")
        if self.reconciled:
            lines.append(f"reconciled: {self.reconciled} call{'' if self.reconciled == 1 else 's'} given up on, "
                         f"{len(self.differed)} of them ended on the node otherwise than the net assumed")
            lines.extend(f"  - {d}" for d in self.differed)
        if self.unreconciled:
            lines.append(f"not reconciled: {len(self.unreconciled)} call{'' if len(self.unreconciled) == 1 else 's'} "
                         "given up on; their nodes could not be asked:")
            lines.extend(f"  - {u}" for u in self.unreconciled)
        for err in self.errors[:max_errors]:
            lines.append(f"error: {err}")
        if len(self.errors) > max_errors:
            lines.append(f"... and {len(self.errors) - max_errors} more errors (petrobot show {self.run_id})")
        return "\n".join(lines)
