"""A session: a task net run to its end on the nodes of a location file (paper sections 2, 4, 5).

* :func:`execute` runs a net: a preflight of its actions on their nodes, the learners (section 4,
  restored from the journal), the runtime, the console and the operator's commands;
* :func:`build_learner` makes the learners of a net, restored from the journal;
* :func:`net_actions` names every primitive action a net may call.

Preflight: before the first firing, every primitive action of the net (every alternative of every
primitive task) must be placed in services.toml and offered by a reachable node that loaded the same
services.toml (:meth:`services.client.ServiceClient.preflight`). Otherwise the run does not start:
:class:`NodesNotReady` lists the problems and nothing is journaled, unless ``degraded`` asks to
start anyway (the calls of the missing actions then end in error and the net takes its error
branches).

``petrobot run`` and ``demo`` are thin commands over these (the nodes themselves:
:mod:`coordinator.nodegroup`).
"""

from __future__ import annotations

import logging

from coordinator.console import Console, read_operator_commands
from coordinator.events import Observer
from coordinator.journal import Journal, JournalReader
from coordinator.learning import Learner
from coordinator.net import PetriNet
from coordinator.runtime import RunSummary, Runtime
from services.client import ServiceClient
from services.errors import PetrobotError
from services.location import Location

log = logging.getLogger("petrobot.run")

__all__ = ["NodesNotReady", "build_learner", "execute", "net_actions"]


class NodesNotReady(PetrobotError):
    """The preflight found actions of the net that no reachable node offers; the run did not start.

    Attributes:
        problems: one sentence per problem (an action not placed, a node unreachable or refusing
            our key, an action its node does not offer, a node running another services.toml).
    """

    def __init__(self, problems: list[str]) -> None:
        self.problems = list(problems)
        n = len(self.problems)
        super().__init__(f"the nodes are not ready for this net ({n} problem{'' if n == 1 else 's'}); "
                         "nothing was run (--degraded starts anyway):\n" + "\n".join(f"  - {p}" for p in self.problems))


def net_actions(net: PetriNet) -> list[str]:
    """Every primitive action of ``net`` (each alternative of each primitive task), in net order."""
    return list(dict.fromkeys(a.name for task in net.tasks.values() for a in task.actions))


def build_learner(net: PetriNet, seed: int, journal: JournalReader) -> Learner:
    """One learning automaton per primitive task (section 4), restored from the journal if saved there
    (a damaged saved state is left out, with a warning naming it: that task's learner starts afresh).

    Raises:
        LearnerConfigError: a task's ``learner`` table or its costs are invalid (names the task).
        JournalError: a saved state is malformed.
    """
    learner = Learner.from_net(net, seed)
    before = journal.damage_count
    saved = {task: saved.state for task, saved in journal.learner_states().items()}
    for line in journal.damage_report()[before:]:
        log.warning("learner state not restored: %s", line)
    if saved:
        learner.restore(saved, strict=False)
    return learner


async def execute(net: PetriNet, *, location: Location, key: bytes, journal: Journal, seed: int = 0,
                  resume: bool = False, net_text: str | None = None, live: bool | None = None,
                  quiet: bool = False, read_input: bool = False, max_seconds: float | None = None,
                  observer: Observer | None = None, console: Console | None = None,
                  wait: bool = False, linger: bool = False, goal: dict[str, int] | None = None,
                  degraded: bool = False) -> RunSummary:
    """Run ``net`` to its end and return the :class:`~coordinator.runtime.RunSummary`.

    ``console`` (a :class:`~coordinator.console.Console`, made from ``live``/``quiet`` if not given)
    shows the run; ``observer``, if given, receives the runtime's events instead and is expected
    to forward them to the console. ``resume`` continues the last resumable run of the net in the
    journal (unfinished, or interrupted).

    ``read_input`` reads operator commands from standard input (a terminal); with it, or with
    ``wait``, the run has an operator: when only an operator command could move it on it waits
    for one instead of ending ``waiting_for_operator``. ``linger`` (with an operator) also waits at
    the home marking while a control place could start more, until ``end``/Ctrl-D. ``goal`` (place →
    tokens) is a marking that ends the run ``completed`` even away from home.

    Before the first firing (of a new or a resumed run) the nodes are checked (the module's
    "Preflight"); with ``degraded`` the problems are printed on the console's stream and the run
    starts anyway.

    Raises:
        NodesNotReady: the preflight found problems and ``degraded`` is False (nothing journaled).
        PetrobotError: nothing to resume; a bad learner configuration.
    """
    recovered = None
    if resume:
        run_id = journal.last_unfinished_run(net.name)
        if run_id is None:
            raise PetrobotError(f"{journal.path}: no unfinished run of net {net.name!r} to resume")
        recovered = journal.recover(net, run_id)
    learner = build_learner(net, recovered.seed if recovered else seed, journal)
    async with ServiceClient(location, key) as client:
        problems = await client.preflight(net_actions(net))
        console = console or Console(net, live=live, quiet=quiet)
        if problems and not degraded:
            raise NodesNotReady(problems)
        for problem in problems:
            print(f"petrobot: starting degraded: {problem}", file=console.stream, flush=True)
        operator = read_input or wait
        runtime = Runtime(net, client, journal, seed=seed, learner=learner, recovered=recovered,
                          net_text=net_text, operator=operator, linger=operator and linger, goal=goal)
        console.attach(runtime)
        if observer is not None:
            runtime.observer = observer
        screen = None
        if console.live:  # the terminal's live view, with the input line when the operator types there
            from coordinator.terminal import LiveScreen

            screen = LiveScreen(console, runtime if read_input else None)
            screen.start()
        elif read_input:
            read_operator_commands(runtime)
        try:
            return await runtime.run(max_seconds=max_seconds)
        finally:
            if screen is not None:
                await screen.stop()
