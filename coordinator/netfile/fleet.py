"""A fleet of N mobile robots sharing two aisles, a lift and chargers, as a task net (pure: text only).

Written as the paper writes a task (Lima et al., sections 3–4): shared resources are places whose
tokens are the free units (``aisle_1_free``, ``lift_free``, ``aisle_2_free``, ``chargers_free``);
each robot's mission is a chain of primitive tasks (``load`` at station A, ``drive`` through aisle 1,
``ride_lift``, ``drive`` through aisle 2, ``unload`` at station B, the way back, ``charge``), each
with its normal exit (``int:<task>.ok``) and its error exit (``int:<task>.error``) into a primitive
task ``recover`` that keeps the resource the robot holds until a person has moved it back to its
parking spot (``recover`` ends either way in ``r<i>_ready``, freeing what the robot held).

A robot that has finished a primitive task waits at its end for the next resource while it holds
the one it is in (``r<i>_waiting_after_drive_1_out``: through aisle 1, waiting in it for the lift;
no primitive task runs there, so no error exit frees it), so robots going opposite ways can block
each other for ever: with two robots, one in
aisle 1 waiting for the lift while the other, in the lift on its way back, waits for aisle 1. That is
the question ``petrobot analyze`` answers for the fleet. ``safe=True`` adds the usual remedy, a
corridor token: a robot enters the aisles-and-lift corridor only with the token and gives it back
when it leaves, so the corridor holds one robot at a time and the fleet is deadlock-free.

``missions=M`` gives each robot M missions (a control place ``r<i>_missions`` of M tokens that its
start takes), so that a run of the net ends: completed once every robot is parked again, stuck if
the fleet deadlocks on the way. Without it the robots go round for ever, the net the analysis is
about. ``services.toml`` places simulated actions for the primitive tasks (services/actions/fleet.py).

The state space grows about fivefold a robot with the corridor token and tenfold without (each
robot loads, charges, recovers or waits, and without the token several are in the corridor at
once): the explicit search answers up to N = 5 unsafe and N = 6 safe, the symbolic engine to N = 20
and beyond (docs/analysis.md, section 9).
"""

from __future__ import annotations

__all__ = ["MAX_ROBOTS", "fleet_toml"]

#: the largest fleet the generator writes
MAX_ROBOTS = 200

_TASKS = {
    "load": ("load_tote", 20.0, 0.995),
    "drive": ("drive_aisle", 15.0, 0.99),
    "ride_lift": ("ride_lift", 25.0, 0.995),
    "unload": ("unload_tote", 20.0, 0.995),
    "charge": ("charge_battery", 300.0, 0.999),
    "recover": ("manual_recovery", 120.0, 0.99),
}


def fleet_toml(robots: int, *, chargers: int | None = None, safe: bool = False, missions: int | None = None) -> str:
    """The fleet's task net as the TOML net format (``petrobot example fleet``).

    Args:
        robots: N ≥ 1 robots.
        chargers: charging stations (default ⌈N / 4⌉).
        safe: add the corridor token (module docstring): deadlock-free.
        missions: M ≥ 1 missions per robot, then the run ends (module docstring); ``None``: endless.

    Returns:
        The net file's text (loads with :func:`coordinator.netfile.loader.loads_net`).

    Raises:
        ValueError: robots outside 1 .. :data:`MAX_ROBOTS`, fewer than one charger, or missions < 1.
    """
    if missions is not None and missions < 1:
        raise ValueError(f"missions must be at least 1, not {missions}")
    if not 1 <= robots <= MAX_ROBOTS:
        raise ValueError(f"robots must be between 1 and {MAX_ROBOTS}, not {robots}")
    chargers = max(1, -(-robots // 4)) if chargers is None else chargers
    if chargers < 1:
        raise ValueError(f"chargers must be at least 1, not {chargers}")
    name = f"fleet_{robots}{'_safe' if safe else ''}"
    home = ", ".join(f"r{i}_ready = 1" for i in range(robots))
    out = [f"# {robots} robots, two aisles, a lift and {chargers} charger(s): coordinator.netfile.fleet",
           "", "[net]", f'name = "{name}"',
           f'description = "{robots} mobile robots sharing two aisles, a lift and {chargers} charger(s)'
           f'{" (one robot in the corridor at a time)" if safe else ""}'
           f'{f", {missions} mission(s) each" if missions else ""}."',
           "format = 1",
           f"home = {{ {home}, aisle_1_free = 1, lift_free = 1, aisle_2_free = 1, chargers_free = {chargers}"
           + (", corridor_free = 1 }" if safe else " }"), ""]

    def place(pid: str, kind: str = "", tokens: int = 0, task: str = "", label: str = "") -> None:
        out.append("[[place]]")
        out.append(f'id = "{pid}"')
        if kind:
            out.append(f'kind = "{kind}"')
        if task:
            out.append(f'task = "{task}"')
        if tokens:
            out.append(f"tokens = {tokens}")
        if label:
            out.append(f'label = "{label}"')
        out.append("")

    def transition(tid: str, inputs: dict[str, int], outputs: dict[str, int], event: str = "",
                   hidden: bool = False) -> None:
        out.append("[[transition]]")
        out.append(f'id = "{tid}"')
        if event:
            out.append(f'events = ["{event}"]')
        if hidden:
            out.append("hidden = true")
        out.append("inputs = { " + ", ".join(f"{p} = {w}" for p, w in inputs.items()) + " }")
        out.append("outputs = { " + ", ".join(f"{p} = {w}" for p, w in outputs.items()) + " }")
        out.append("")

    for pid, tokens, label in (("aisle_1_free", 1, "aisle 1 free (capacity one)"),
                               ("lift_free", 1, "lift free"), ("aisle_2_free", 1, "aisle 2 free (capacity one)"),
                               ("chargers_free", chargers, "free chargers")):
        place(pid, "resource", tokens, label=label)
    if safe:
        place("corridor_free", "resource", 1, label="corridor (aisles and lift) free")
    ticket = {"corridor_free": 1} if safe else {}
    # each step: (place suffix, task, resource held while in it, resource taken to leave it,
    # whether leaving it releases the held resource, corridor ticket given back on leaving)
    steps = [("loading", "load", None), ("drive_1_out", "drive", "aisle_1_free"),
             ("lift_up", "ride_lift", "lift_free"), ("drive_2_out", "drive", "aisle_2_free"),
             ("unloading", "unload", None), ("drive_2_back", "drive", "aisle_2_free"),
             ("lift_down", "ride_lift", "lift_free"), ("drive_1_back", "drive", "aisle_1_free"),
             ("charging", "charge", "chargers_free")]
    for i in range(robots):
        r = f"r{i}"
        place(f"{r}_ready", "resource", 1, label=f"robot {i} parked, ready")
        for suffix, task, _ in steps:
            place(f"{r}_{suffix}", "primitive_task", task=task, label=f"robot {i}: {suffix.replace('_', ' ')}")
            place(f"{r}_recover_{suffix}", "primitive_task", task="recover",
                  label=f"robot {i}: recovery after {suffix.replace('_', ' ')}")
        start = {f"{r}_ready": 1}
        if missions:
            place(f"{r}_missions", "control", missions, label=f"missions left for robot {i}")
            start[f"{r}_missions"] = 1
        transition(f"{r}_start", start, {f"{r}_loading": 1})
        for k, (suffix, task, held) in enumerate(steps):
            here = f"{r}_{suffix}"
            nxt = steps[k + 1] if k + 1 < len(steps) else None
            inputs = {here: 1}
            outputs: dict[str, int] = {}
            if nxt is None:
                outputs[f"{r}_ready"] = 1
            else:
                outputs[f"{r}_{nxt[0]}"] = 1
                if nxt[2] is not None and nxt[2] != held:
                    inputs[nxt[2]] = 1  # wait here for the next resource, holding this one
                if k == 0:
                    inputs.update(ticket)  # into the corridor
            if held is not None and (nxt is None or nxt[2] != held):
                outputs[held] = outputs.get(held, 0) + 1
            if suffix == "drive_1_back":
                outputs.update(ticket)  # out of the corridor, into a charger
            if len(inputs) > 1:  # the task is done; the robot waits at its end for the next resource
                wait = f"{r}_waiting_after_{suffix}"
                place(wait, label=f"robot {i}: {suffix.replace('_', ' ')} done, waiting for {nxt[2] if nxt else ''}")
                transition(f"{here}_ok", {here: 1}, {wait: 1}, event=f"int:{task}.ok")
                inputs[wait] = inputs.pop(here)
                transition(f"{r}_leave_{suffix}", inputs, outputs)
            else:
                transition(f"{here}_ok", inputs, outputs, event=f"int:{task}.ok")
            transition(f"{here}_failed", {here: 1}, {f"{r}_recover_{suffix}": 1}, event=f"int:{task}.error",
                       hidden=True)
            back = {f"{r}_ready": 1}
            if held is not None:
                back[held] = 1
            if safe and 1 <= k <= 7:
                back.update(ticket)
            for outcome in ("ok", "error"):
                transition(f"{r}_recover_{suffix}_{outcome}", {f"{r}_recover_{suffix}": 1}, back,
                           event=f"int:recover.{outcome}", hidden=outcome == "error")
    for task, (action, mean, reliability) in _TASKS.items():
        out += [f"[task.{task}]", f'actions = ["{action}"]', f"deadline_s = {4 * mean:g}", f"mean_time_s = {mean:g}",
                f"reliability = {reliability}", ""]
    return "\n".join(out)
