"""What `ros2 param list/get/set` show, for the parameter tests and people: calls a node's
rcl_interfaces services (ListParameters, GetParameters, SetParameters) and prints the answers,
one line per action.

    python test/support/param_probe.py ACTION [ACTION ...]

Actions (each word-separated inside one argument):
  get NODE [NAME ...]         prints ``PARAMS NODE <json {name: value}>``: the named parameters,
                              or every declared one (ListParameters) when no name is given; a
                              name the node does not declare is absent
  describe NODE NAME ...      prints ``DESCRIBE NODE <json {name: {read_only, range}}>`` (range:
                              [from, to] of its floating-point or integer range, or null)
  set NODE NAME VALUE         VALUE is a Python literal (``2.0``, ``'x'``); prints
                              ``SET NODE NAME <successful> <reason>``
  diagnostic NODE KEY VALUE   waits until NODE's status on /diagnostics reports KEY = VALUE;
                              prints ``DIAGNOSTIC NODE KEY VALUE``
Every wait is bounded (60 s): the probe exits 3 when one runs out.
"""

import ast
import json
import sys
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.srv import (
    DescribeParameters,
    GetParameters,
    ListParameters,
    SetParameters,
)
from rclpy.node import Node
from rclpy.parameter import Parameter, parameter_value_to_python

from polymatch_ros.ros.wire.service_call import call_service

BOUND = 60.0


class Probe:
    def __init__(self):
        self.node = Node("param_probe")
        self.diagnostics = {}  # hardware_id (the node) -> {key: value}
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._diagnostics, 10)

    def _diagnostics(self, msg):
        for status in msg.status:
            self.diagnostics[status.hardware_id] = {kv.key: kv.value for kv in status.values}

    def call(self, kind, node, request):
        answer = call_service(self.node, kind, f"{node}/{_SERVICE[kind]}", request, BOUND)
        if not answer.answered:
            fail(answer.failure)
        return answer.response

    def get(self, node, *names):
        if not names:
            names = self.call(ListParameters, node, ListParameters.Request()).result.names
        answer = self.call(GetParameters, node, GetParameters.Request(names=list(names)))
        values = {n: parameter_value_to_python(v) for n, v in zip(names, answer.values)}
        values = {n: list(v) if hasattr(v, "tolist") or isinstance(v, tuple) else v
                  for n, v in values.items() if v is not None}
        print(f"PARAMS {node} {json.dumps(values, sort_keys=True)}", flush=True)

    def describe(self, node, *names):
        answer = self.call(DescribeParameters, node, DescribeParameters.Request(names=list(names)))
        out = {}
        for d in answer.descriptors:
            ranges = list(d.floating_point_range) + list(d.integer_range)
            out[d.name] = {"read_only": d.read_only,
                           "range": [ranges[0].from_value, ranges[0].to_value] if ranges else None}
        print(f"DESCRIBE {node} {json.dumps(out, sort_keys=True)}", flush=True)

    def set(self, node, name, text):
        param = Parameter(name, value=ast.literal_eval(text)).to_parameter_msg()
        result = self.call(SetParameters, node, SetParameters.Request(parameters=[param]))
        answer = result.results[0]
        print(f"SET {node} {name} {answer.successful} {answer.reason}", flush=True)

    def diagnostic(self, node, key, value):
        end = time.monotonic() + BOUND
        while self.diagnostics.get(node, {}).get(key) != value:
            if time.monotonic() > end:
                fail(f"{node}: {key} = {self.diagnostics.get(node, {}).get(key)!r}, not {value}")
            rclpy.spin_once(self.node, timeout_sec=0.1)
        print(f"DIAGNOSTIC {node} {key} {value}", flush=True)


_SERVICE = {ListParameters: "list_parameters", GetParameters: "get_parameters",
            SetParameters: "set_parameters", DescribeParameters: "describe_parameters"}


def fail(text):
    print(f"probe: {text}", flush=True)
    sys.exit(3)


def main(actions):
    rclpy.init()
    probe = Probe()
    for action in actions:
        word, *args = action.split()
        getattr(probe, word)(*args)
    probe.node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main(sys.argv[1:])
