"""A stand-in ROS 2 robot built on zenoh-ros2-sdk: the ROS 2 tutorials' interfaces over rmw_zenoh.

What a ROS 2 Jazzy machine running ``examples_rclcpp_minimal_action_server`` and
``examples_rclpy_minimal_service`` with ``RMW_IMPLEMENTATION=rmw_zenoh_cpp`` would offer, served by
the pure-Python zenoh-ros2-sdk (an implementation petrobot did not write), so that petrobot's ROS 2
reach is exercised against someone else's reading of the rmw_zenoh wire:

* the service ``/add_two_ints`` (``example_interfaces/srv/AddTwoInts``);
* the action ``/fibonacci`` (``example_interfaces/action/Fibonacci``), composed as rcl_action does
  of the services ``/fibonacci/_action/send_goal``, ``cancel_goal``, ``get_result`` and the topics
  ``/fibonacci/_action/feedback`` and ``/fibonacci/_action/status`` (transient local): a goal of
  order ``n`` (0..46, else rejected) computes the sequence one term per ``step_s`` seconds,
  publishing each partial sequence as feedback, and ends SUCCEEDED, or CANCELED at the next step
  after a cancel request;
* the topic ``/crossfire`` (``std_msgs/msg/Bool``), published at ``rate_hz``: false, and true while a
  ball is in the crossfire (every ``period_s`` for ``pulse_s``, or on command);
* a base that drives on ``/cmd_vel`` (``geometry_msgs/msg/Twist``): each command moves it forward by
  ``linear.x`` times the time since the previous one (at most 0.2 s), and ``/docked``
  (``std_msgs/msg/Bool``, published with ``/crossfire``) says whether it has travelled ``dock_m``.

The SDK is given the definitions petrobot ships (``services/ros2/definitions``) and is never allowed
to fetch any from git (:func:`forbid_fetching`). The action's type hashes are the ones the
generated code of ``example_interfaces`` carries on a Jazzy machine (:data:`JAZZY_HASHES`); the
SDK computes the others itself.

Everything the robot sees and does is printed as JSON lines (``ready``, ``service``, ``goal``,
``executing``, ``cancel``, ``result``, ``crossfire``, ``cmd_vel`` (every 10th), ``docked``) so that a test can compare it with petrobot's journal.
"""

from __future__ import annotations

import json
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np

__all__ = ["JAZZY_HASHES", "MAX_ORDER", "Ros2Robot", "forbid_fetching"]

DEFINITIONS = Path(__file__).resolve().parents[2] / "services" / "ros2" / "definitions"

JAZZY_HASHES = {
    "example_interfaces/action/Fibonacci_SendGoal":
        "RIHS01_d1a57fb2a4afe8c21e34fb10db206f16ce6729b28531141472df92277c55b557",
    "example_interfaces/action/Fibonacci_GetResult":
        "RIHS01_1b0de0d5d29dc955d92f546706568428632771db13ec84c15ec1c1a59f424a57",
    "example_interfaces/action/Fibonacci_FeedbackMessage":
        "RIHS01_c1de71afd52e49a89c53d8262366884185bc0a02f78ce051c4e46b0a7fe59bb2",
    "action_msgs/srv/CancelGoal": "RIHS01_573d8b0a534451d7bc2ac8c5ffde8ac14b8593b7001175d0cd6516dcbeb8689a",
    "action_msgs/msg/GoalStatusArray": "RIHS01_6c1684b00f177d37438febe6e709fc4e2b0d4248dca4854946f9ed8b30cda83e",
}
"""RIHS01 hashes of the action's parts, as the rosidl-generated code of a Jazzy machine has them."""

MAX_ORDER = 46
"""The largest order whose sequence fits int32; larger goals are rejected."""

SUCCEEDED, CANCELED, EXECUTING, ACCEPTED, UNKNOWN = 4, 5, 2, 1, 0
CANCEL_NONE, CANCEL_UNKNOWN_GOAL, CANCEL_TERMINATED = 0, 2, 3


def forbid_fetching() -> None:
    """Make zenoh-ros2-sdk fail loudly instead of cloning interface repositories from the network:
    every definition the robot needs is in the repository."""
    from zenoh_ros2_sdk import message_registry

    def refuse(*args: Any, **kwargs: Any) -> Any:
        raise RuntimeError(f"zenoh-ros2-sdk tried to fetch interface definitions ({args}); they must come from "
                           f"{DEFINITIONS}")

    message_registry.clone_to_cache = refuse
    message_registry.get_message_file_path = refuse
    message_registry.get_registry(str(DEFINITIONS))


@dataclass
class _Goal:
    goal_id: bytes
    order: int
    stamp: tuple[int, int]
    status: int = ACCEPTED
    sequence: list[int] = field(default_factory=list)
    cancel: threading.Event = field(default_factory=threading.Event)
    done: threading.Event = field(default_factory=threading.Event)


class Ros2Robot:
    """The stand-in robot (see the module docstring).

    Args:
        router: the Zenoh router's address, ``(host, port)``.
        out: where the JSON event lines go.
        step_s: seconds per Fibonacci term.
        rate_hz: /crossfire messages per second.
        period_s: a ball crosses every ``period_s`` seconds (0: only on command).
        pulse_s: how long the crossfire sees it, seconds.
        node_name: the ROS 2 node name of the robot.
        dock_m: the distance the base drives before it is docked, metres.
    """

    def __init__(self, router: tuple[str, int], out: TextIO, *, step_s: float = 0.1, rate_hz: float = 20.0,
                 period_s: float = 0.0, pulse_s: float = 0.3, node_name: str = "stand_in_robot",
                 dock_m: float = 1.0) -> None:
        forbid_fetching()
        from zenoh_ros2_sdk import ROS2Publisher, ROS2ServiceServer, ROS2Subscriber
        from zenoh_ros2_sdk.qos import QosDurability, QosProfile
        from zenoh_ros2_sdk.session import ZenohSession

        self.out = out
        self._out_lock = threading.Lock()
        self.step_s = step_s
        self.rate_hz = rate_hz
        self.period_s = period_s
        self.pulse_s = pulse_s
        self.goals: dict[bytes, _Goal] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._crossfire_forced: bool | None = None
        self.dock_m = dock_m
        self.travelled = 0.0
        self.commands = 0
        self._last_command: float | None = None
        host, port = router
        self.sdk = ZenohSession.get_instance(host, port)
        self._types = self._register()
        common = {"router_ip": host, "router_port": port, "node_name": node_name}
        action = "/fibonacci/_action"
        self._servers = [
            ROS2ServiceServer("/add_two_ints", "example_interfaces/srv/AddTwoInts", callback=self._add,
                              request_definition="int64 a\nint64 b", response_definition="int64 sum", **common),
            ROS2ServiceServer(f"{action}/send_goal", "example_interfaces/action/Fibonacci_SendGoal",
                              callback=self._send_goal, type_hash=JAZZY_HASHES[
                                  "example_interfaces/action/Fibonacci_SendGoal"],
                              request_definition="unique_identifier_msgs/msg/UUID goal_id\n"
                                                 "example_interfaces/msg/Fibonacci_Goal goal",
                              response_definition="bool accepted\nbuiltin_interfaces/msg/Time stamp", **common),
            ROS2ServiceServer(f"{action}/cancel_goal", "action_msgs/srv/CancelGoal", callback=self._cancel_goal,
                              type_hash=JAZZY_HASHES["action_msgs/srv/CancelGoal"],
                              request_definition="action_msgs/msg/GoalInfo goal_info",
                              response_definition="int8 return_code\naction_msgs/msg/GoalInfo[] goals_canceling",
                              **common),
        ]
        self._results = ROS2ServiceServer(
            f"{action}/get_result", "example_interfaces/action/Fibonacci_GetResult", mode="queue",
            type_hash=JAZZY_HASHES["example_interfaces/action/Fibonacci_GetResult"],
            request_definition="unique_identifier_msgs/msg/UUID goal_id",
            response_definition="int8 status\nexample_interfaces/msg/Fibonacci_Result result", **common)
        self._feedback = ROS2Publisher(
            f"{action}/feedback", "example_interfaces/action/Fibonacci_FeedbackMessage",
            msg_definition="unique_identifier_msgs/msg/UUID goal_id\nexample_interfaces/msg/Fibonacci_Feedback feedback",
            type_hash=JAZZY_HASHES["example_interfaces/action/Fibonacci_FeedbackMessage"], **common)
        self._status = ROS2Publisher(
            f"{action}/status", "action_msgs/msg/GoalStatusArray",
            msg_definition="action_msgs/msg/GoalStatus[] status_list",
            type_hash=JAZZY_HASHES["action_msgs/msg/GoalStatusArray"],
            qos=QosProfile(durability=QosDurability.TRANSIENT_LOCAL, history_depth=1), **common)
        self._crossfire = ROS2Publisher("/crossfire", "std_msgs/msg/Bool", msg_definition="bool data", **common)
        self._docked = ROS2Publisher("/docked", "std_msgs/msg/Bool", msg_definition="bool data", **common)
        self._cmd_vel = ROS2Subscriber("/cmd_vel", "geometry_msgs/msg/Twist", self._drive, **common)
        self._threads = [threading.Thread(target=self._serve_results, name="get_result", daemon=True),
                         threading.Thread(target=self._publish_crossfire, name="crossfire", daemon=True)]
        for thread in self._threads:
            thread.start()

    def _register(self) -> dict[str, Any]:
        """Register the nested types the action's definitions use (from the shipped files)."""
        names = ["builtin_interfaces/msg/Time", "unique_identifier_msgs/msg/UUID", "action_msgs/msg/GoalInfo",
                 "action_msgs/msg/GoalStatus"]
        for name in names:
            pkg, _, short = name.split("/")
            self.sdk.register_message_type((DEFINITIONS / pkg / "msg" / f"{short}.msg").read_text(), name)
        text = (DEFINITIONS / "example_interfaces" / "action" / "Fibonacci.action").read_text()
        goal, result, feedback = text.split("\n---\n")
        for part, definition in (("Goal", goal), ("Result", result), ("Feedback", feedback)):
            self.sdk.register_message_type(definition, f"example_interfaces/msg/Fibonacci_{part}")
        return {n: self.sdk.store.types[n] for n in [
            *names, "example_interfaces/msg/Fibonacci_Result", "example_interfaces/msg/Fibonacci_Feedback"]}

    # ---- output

    def emit(self, event: str, **data: Any) -> None:
        """One JSON line on the output."""
        line = json.dumps({"event": event, "t": round(time.time(), 6), **data})
        with self._out_lock:
            self.out.write(line + "\n")
            self.out.flush()

    # ---- AddTwoInts

    def _add(self, request: Any) -> Any:
        total = int(request.a) + int(request.b)
        self.emit("service", service="/add_two_ints", a=int(request.a), b=int(request.b), sum=total)
        return self._servers[0].response_msg_class(sum=total)

    # ---- Fibonacci

    def _uuid(self, goal_id: bytes) -> Any:
        return self._types["unique_identifier_msgs/msg/UUID"](uuid=np.frombuffer(goal_id, dtype=np.uint8).copy())

    def _send_goal(self, request: Any) -> Any:
        goal_id = bytes(request.goal_id.uuid)
        order = int(request.goal.order)
        now = time.time_ns()
        stamp = (now // 1_000_000_000, now % 1_000_000_000)
        accepted = 0 <= order <= MAX_ORDER and goal_id not in self.goals
        self.emit("goal", goal_id=goal_id.hex(), order=order, accepted=accepted)
        if accepted:
            goal = _Goal(goal_id, order, stamp)
            with self._lock:
                self.goals[goal_id] = goal
            self._publish_status()
            threading.Thread(target=self._execute, args=(goal,), name=f"goal-{goal_id.hex()[:8]}", daemon=True).start()
        time_type = self._types["builtin_interfaces/msg/Time"]
        return self._servers[1].response_msg_class(accepted=accepted, stamp=time_type(sec=stamp[0], nanosec=stamp[1]))

    def _execute(self, goal: _Goal) -> None:
        goal.status = EXECUTING
        self._publish_status()
        self.emit("executing", goal_id=goal.goal_id.hex())
        sequence = [0, 1]
        feedback_type = self._types["example_interfaces/msg/Fibonacci_Feedback"]
        for i in range(1, goal.order):
            if goal.cancel.wait(self.step_s):
                break
            sequence.append(sequence[i] + sequence[i - 1])
            self._feedback.publish(goal_id=self._uuid(goal.goal_id),
                                   feedback=feedback_type(sequence=np.array(sequence, dtype=np.int32)))
        goal.sequence = sequence[: goal.order + 1] if goal.order < 2 else sequence
        goal.status = CANCELED if goal.cancel.is_set() else SUCCEEDED
        self.emit("result", goal_id=goal.goal_id.hex(), status={SUCCEEDED: "SUCCEEDED", CANCELED: "CANCELED"}[goal.status],
                  sequence=goal.sequence)
        self._publish_status()
        goal.done.set()

    def _cancel_goal(self, request: Any) -> Any:
        goal_id = bytes(request.goal_info.goal_id.uuid)
        with self._lock:
            goal = self.goals.get(goal_id)
        info_type = self._types["action_msgs/msg/GoalInfo"]
        canceling = []
        if goal is None:
            code = CANCEL_UNKNOWN_GOAL
        elif goal.done.is_set():
            code = CANCEL_TERMINATED
        else:
            code = CANCEL_NONE
            goal.cancel.set()
            canceling.append(info_type(goal_id=self._uuid(goal_id),
                                       stamp=self._types["builtin_interfaces/msg/Time"](sec=goal.stamp[0],
                                                                                       nanosec=goal.stamp[1])))
        self.emit("cancel", goal_id=goal_id.hex(), return_code=code)
        return self._servers[2].response_msg_class(return_code=code, goals_canceling=canceling)

    def _serve_results(self) -> None:
        while not self._stop.is_set():
            try:
                key, request = self._results.take_request(timeout=0.2)
            except TimeoutError:
                continue
            goal_id = bytes(request.goal_id.uuid)
            threading.Thread(target=self._answer_result, args=(key, goal_id), daemon=True).start()

    def _answer_result(self, key: Any, goal_id: bytes) -> None:
        with self._lock:
            goal = self.goals.get(goal_id)
        result_type = self._types["example_interfaces/msg/Fibonacci_Result"]
        if goal is None:
            status, sequence = UNKNOWN, []
        else:
            while not goal.done.wait(0.2):
                if self._stop.is_set():
                    return
            status, sequence = goal.status, goal.sequence
        response = self._results.response_msg_class(status=status,
                                                    result=result_type(sequence=np.array(sequence, dtype=np.int32)))
        self._results.send_response(key, response)

    def _publish_status(self) -> None:
        status_type = self._types["action_msgs/msg/GoalStatus"]
        info_type = self._types["action_msgs/msg/GoalInfo"]
        time_type = self._types["builtin_interfaces/msg/Time"]
        with self._lock:
            entries = [status_type(goal_info=info_type(goal_id=self._uuid(g.goal_id),
                                                       stamp=time_type(sec=g.stamp[0], nanosec=g.stamp[1])),
                                   status=g.status) for g in self.goals.values()]
        self._status.publish(status_list=entries)

    # ---- the base

    def _drive(self, twist: Any) -> None:
        now = time.monotonic()
        dt = 0.0 if self._last_command is None else min(0.2, now - self._last_command)
        self._last_command = now
        with self._lock:
            before = self.travelled
            self.travelled += float(twist.linear.x) * dt
            self.commands += 1
            count, travelled = self.commands, self.travelled
        if count % 10 == 1:
            self.emit("cmd_vel", count=count, linear_x=float(twist.linear.x), travelled=round(travelled, 4))
        if before < self.dock_m <= travelled:
            self.emit("docked", commands=count, travelled=round(travelled, 4))

    # ---- crossfire

    def force_crossfire(self, value: bool | None) -> None:
        """Publish ``value`` on /crossfire from now on (``None``: back to the periodic pulses)."""
        self._crossfire_forced = value

    def _publish_crossfire(self) -> None:
        start = time.monotonic()
        last: bool | None = None
        while not self._stop.wait(1.0 / self.rate_hz):
            forced = self._crossfire_forced
            if forced is not None:
                value = forced
            elif self.period_s > 0:
                value = (time.monotonic() - start) % self.period_s < self.pulse_s
            else:
                value = False
            self._crossfire.publish(data=value)
            self._docked.publish(data=self.travelled >= self.dock_m)
            if value != last:
                self.emit("crossfire", data=value)
                last = value

    # ---- lifecycle

    def ready(self, **data: Any) -> None:
        """Say that every interface is served."""
        self.emit("ready", node=self._servers[0].node_name, services=["/add_two_ints"], actions=["/fibonacci"],
                  topics=["/crossfire", "/docked"], subscriptions=["/cmd_vel"], **data)

    def close(self) -> None:
        """Stop the threads, withdraw every interface, close the session."""
        self._stop.set()
        for thread in self._threads:
            thread.join(timeout=2.0)
        for endpoint in [*self._servers, self._results, self._feedback, self._status, self._crossfire, self._docked,
                         self._cmd_vel]:
            endpoint.close()
        self.sdk.session.close()

