"""Execution of an interpreted Petri net, without I/O (paper section 2).

* :mod:`coordinator.engine.effects` — the vocabulary: :class:`EngineState`, :class:`Instance`,
  the effect records :class:`Firing`, :class:`StartAction`, :class:`CancelAction` and the
  :data:`Chooser` of primitive actions;
* :mod:`coordinator.engine.tables` — :class:`EngineTables`, the lookups compiled from a net once;
* :mod:`coordinator.engine.engine` — :class:`Engine`, the executor;
* :mod:`coordinator.engine.rest` — :func:`~coordinator.engine.rest.at_rest`: what a run that has
  come to rest looks like (home, stuck places, what the operator could do).
"""

from coordinator.engine.effects import (
    CancelAction,
    Chooser,
    Effect,
    EngineState,
    Firing,
    Instance,
    OperatorOption,
    StartAction,
)
from coordinator.engine.engine import Engine
from coordinator.engine.tables import EngineTables

__all__ = [
    "CancelAction",
    "Chooser",
    "Effect",
    "Engine",
    "EngineState",
    "EngineTables",
    "Firing",
    "Instance",
    "OperatorOption",
    "StartAction",
]
