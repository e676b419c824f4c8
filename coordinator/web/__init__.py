"""The operator console in a browser (paper section 5): draw a task net, follow and steer its run.

"A robotic task can be designed through a graphical interface, by drawing the corresponding Petri
net [...]. Task execution can be followed in real time through the same graphical interface, by
following the token flow in the Petri net. The operator can change the task execution path and/or
timing by token removal/insertion in special places." This package is that interface, served by
petrobot itself on the coordinator's event loop (docs/console.md):

* :mod:`~coordinator.web.server` — the aiohttp server: page, JSON API, WebSocket, security;
* :mod:`~coordinator.web.protocol` — the WebSocket protocol: every inbound message checked;
* :mod:`~coordinator.web.frames` — :class:`LiveFeed`, the run's events coalesced into frames;
* :mod:`~coordinator.web.draft` — a drawn net as TOML, checked like ``petrobot check``;
* :mod:`~coordinator.web.files` — opening, saving and exporting net files under one folder;
* :mod:`~coordinator.web.autolayout` — a first drawing for a net without positions;
* :mod:`~coordinator.web.replay` — a run's timeline from the journal;
* :mod:`~coordinator.web.analysis` — ``analyze``, ``gspn``, ``perf`` and ``learn`` for the page;
* ``static/`` — the page (HTML, CSS, its modules) and the vendored libraries (``VENDORED.md``).

The terminal view (:mod:`coordinator.console`) and this one observe the same runtime side by side
(:meth:`coordinator.runtime.Runtime.add_observer`); commands from either take the same engine path
and land in the same journal.
"""

__all__: list[str] = []  # the modules above are imported by name; the package itself exports nothing
