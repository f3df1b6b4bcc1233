"""`polymatch set NAME VALUE`: one runtime parameter on every agent of an ensemble, one command.

    polymatch set kappa 2.0                 # every agent node in /polymatch
    polymatch set max_linear_speed 0.3 --ensemble team_b

It finds the agent processes' nodes of the ensemble (``agent_<i>``, ``agents_<first>_<last>``;
not the nodes a packed process gives each of its agents) in the ROS graph and calls each
one's ``set_parameters`` service (``rcl_interfaces/srv/SetParameters``), as ``ros2 param set``
would one at a time.  The value is checked against the parameter's range
here first (``params.check_value``; a bad one is a one-line error, exit 2, nothing sent);
each agent checks it again and applies it at its next tick (``runtime_params``).  One line per
agent node, with the value it reads back (``get_parameters``, as ``ros2 param get``); exit 0
if every one accepted, 2 if one refused (lockstep agents refuse: their parameters are
read-only), 1 if no agent answered within ``--timeout``.
"""

from __future__ import annotations

import os
import re
import time
from typing import TYPE_CHECKING, Any

from ...core.errors import ParameterError, PolymatchError
from .. import wire
from ..config.params import RUNTIME, check_value
from ..config.runtime_params import SPEC
from ..network.environment import ros_environment
from ..process.teardown import teardown_watchdog
from ..wire.service_call import ServiceCall

if TYPE_CHECKING:
    from rclpy.executors import Executor
    from rclpy.node import Node

#: a set_parameters answer: (accepted, reason), None while none came
Answer = tuple[bool, str] | None

SETTLE_SECONDS = 1.0  # the graph must stay unchanged this long before the calls go out
RESEND_SECONDS = 2.0  # an answer can be lost (see lifecycle_driver): the same value again
READ_BACK_SECONDS = 5.0  # for the accepted value as each agent reads it (get_parameters)


def checked_value(name: str, text: str) -> float:
    """The float value of ``text`` for runtime parameter ``name``; ParameterError otherwise."""
    if name not in RUNTIME:
        raise ParameterError(
            f"{name!r} cannot be set while running; runtime parameters: {', '.join(RUNTIME)}"
        )
    try:
        value = float(text)
    except ValueError:
        raise ParameterError(f"{name}: {text!r} is not a number") from None
    return float(check_value(SPEC[name], value))


AGENT_NODE = re.compile(r"agent_\d+|agents_\d+_\d+")  # not their lean nodes (``_peers``, ...)


def agent_nodes(node: Node, namespace: str) -> list[str]:
    """Names of the agent nodes in ``namespace`` (sorted)."""
    return sorted(
        name for name, space in node.get_node_names_and_namespaces()
        if space == namespace and AGENT_NODE.fullmatch(name)
    )


def _discover(node: Node, executor: Executor, namespace: str, deadline: float) -> list[str]:
    """The agent nodes of the ensemble, once they are all found (or at the deadline).

    Each agent process publishes its run record once a second on the status topic (latched):
    its agents, the ensemble's size and its node name.  When the records cover every agent of
    the ensemble and each recording node is in the graph, the search ends at once.  An
    ensemble of which only some agents run ends when the graph has not changed for
    SETTLE_SECONDS and holds every node that sent a record.
    """
    records: dict[str, wire.RunRecord] = {}

    def heard(msg: Any) -> None:
        rec = wire.RunRecord.from_msg(msg)
        if rec is not None and rec.role == "agent" and rec.node.startswith(namespace + "/"):
            records[rec.node.rsplit("/", 1)[-1]] = rec

    sub = wire.subscription(node, "status", heard)
    seen: list[str] = []
    since = time.monotonic()
    while time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.1)
        now = agent_nodes(node, namespace)
        if now != seen:
            seen, since = now, time.monotonic()
        if records and not _not_found(records, seen):
            break
        if seen and time.monotonic() - since >= SETTLE_SECONDS and set(records) <= set(seen):
            break
    node.destroy_subscription(sub)
    # a packed process's agents have nodes of their own (``agents.hosted``), read-only: its
    # runtime parameters are set on the process node, which steps them
    hosted = {f"agent_{a}" for name, rec in records.items() for a in rec.agents
              if name != f"agent_{a}"}
    return [name for name in seen if name not in hosted]


def _not_found(records: dict[str, wire.RunRecord], names: list[str]) -> list[int]:
    """Agents of the ensemble whose node the records and the graph do not both show yet."""
    n = max((rec.n_agents for rec in records.values()), default=0)
    found = {a for name, rec in records.items() if name in names for a in rec.agents}
    return sorted(set(range(n)) - found)


def _ask_all(node: Node, executor: Executor, kind: Any, service: str, request: Any,
             names: list[str], deadline: float) -> dict[str, Any]:
    """{node name: its answer to ``request`` on its ``service`` (None: none came)}, asked of
    every node at once, each request sent again when its answer is overdue."""
    namespace = node.get_namespace()
    calls = {n: ServiceCall(node, kind, f"{namespace}/{n}/{service}", request, RESEND_SECONDS)
             for n in names}
    try:
        while time.monotonic() < deadline and not all([c.poll() for c in calls.values()]):
            executor.spin_once(timeout_sec=0.05)
    finally:
        for call in calls.values():
            call.close()
    return {n: call.response for n, call in calls.items()}


def _call_all(node: Node, executor: Executor, names: list[str], name: str, value: float,
              deadline: float) -> dict[str, Answer]:
    """{node name: (accepted, reason)} of the set_parameters calls (None: no answer)."""
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    request = SetParameters.Request(parameters=[Parameter(
        name=name,
        value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value),
    )])
    answers = _ask_all(node, executor, SetParameters, "set_parameters", request, names, deadline)
    return {n: None if a is None else (a.results[0].successful, a.results[0].reason)
            for n, a in answers.items()}


def _read_back(node: Node, executor: Executor, names: list[str], name: str) -> dict[str, Any]:
    """{node name: the value parameter ``name`` reads now (get_parameters; None: no answer)}."""
    from rcl_interfaces.srv import GetParameters
    from rclpy.parameter import parameter_value_to_python

    request = GetParameters.Request(names=[name])
    answers = _ask_all(node, executor, GetParameters, "get_parameters", request, names,
                       time.monotonic() + READ_BACK_SECONDS)
    return {n: None if a is None else parameter_value_to_python(a.values[0])
            for n, a in answers.items()}


def set_parameter(name: str, text: str, ensemble: str, timeout: float) -> int:
    """Set runtime parameter ``name`` to ``text`` on every agent node of ``ensemble``; the exit
    code (one line per agent node printed).  The caller ends the process with it
    (``teardown.end_process``): rclpy ran in this process."""
    value = checked_value(name, text)
    namespace = wire.namespace(ensemble)
    os.environ.update(ros_environment())  # loopback discovery unless the user set otherwise
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    rclpy.init(args=[])
    node = Node("polymatch_set", namespace=namespace, start_parameter_services=False)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    code = 1
    try:
        deadline = time.monotonic() + timeout
        names = _discover(node, executor, namespace, deadline)
        if not names:
            raise PolymatchError(
                f"no agent node in {namespace} within {timeout:g} s "
                f"(ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0')})"
            )
        answers = _call_all(node, executor, names, name, value, deadline)
        accepted = [n for n, answer in answers.items() if answer is not None and answer[0]]
        code = _report(answers, name, _read_back(node, executor, accepted, name))
    finally:
        with teardown_watchdog(exit_code=code):
            executor.shutdown(timeout_sec=1.0)
            node.destroy_node()
            if rclpy.ok():
                rclpy.shutdown()
    return code


def _report(answers: dict[str, Answer], name: str, read: dict[str, Any]) -> int:
    """One line per agent node (an accepted value as the node reads it back); the exit code."""
    for n, answer in answers.items():
        if answer is None:
            print(f"{n}: no answer", flush=True)
        elif answer[0] and read.get(n) is None:
            print(f"{n}: {name} accepted, not read back (applied at its next tick)", flush=True)
        elif answer[0]:
            print(f"{n}: {name} = {read[n]:g} (applied at its next tick)", flush=True)
        else:
            print(f"{n}: refused: {answer[1]}", flush=True)
    if any(a is not None and not a[0] for a in answers.values()):
        return 2
    return 0 if all(a is not None for a in answers.values()) else 1
