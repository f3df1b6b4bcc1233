"""One call of a ROS service, bounded: wait for its server, send, take the answer, send again
when the answer is overdue (a reliable answer can still be lost while a server starts).

``ServiceCall`` is polled from a loop that spins the node (``polymatch set`` asks every agent
node at once); ``call_service`` spins until the answer or the timeout (the tests' probes).
Both give a typed ``ServiceAnswer``: the response, or why there is none.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Generic, TypeVar

if TYPE_CHECKING:
    from rclpy.node import Node
    from rclpy.task import Future

Response = TypeVar("Response")

#: an answer not come this long after its request is taken as lost: the request goes again
RESEND_SECONDS = 2.0


@dataclass(frozen=True)
class ServiceAnswer(Generic[Response]):
    """A service's ``response``, or None and the one-line ``failure`` that says why."""

    name: str
    response: Response | None
    failure: str = ""

    @property
    def answered(self) -> bool:
        return self.response is not None


class ServiceCall:
    """One request to the service ``name`` of type ``kind``, advanced by ``poll``."""

    def __init__(self, node: Node, kind: Any, name: str, request: Any,
                 resend_after: float = RESEND_SECONDS) -> None:
        self.node, self.name, self.request = node, name, request
        self.resend_after = resend_after
        self.client = node.create_client(kind, name)
        self.future: Future | None = None
        self.sent = 0.0
        self.response: Any = None

    def poll(self) -> bool:
        """Send once the server is up, take the answer, send again if it is overdue; True
        once answered.  The caller spins the node between polls."""
        if self.response is not None:
            return True
        now = time.monotonic()
        if self.future is not None and self.future.done():
            self.response, self.future = self.future.result(), None
            if self.response is not None:
                return True
        if self.future is not None and now - self.sent > self.resend_after:
            self.client.remove_pending_request(self.future)   # a lost answer: ask again
            self.future = None
        if self.future is None and self.client.service_is_ready():
            self.future, self.sent = self.client.call_async(self.request), now
        return False

    def answer(self) -> ServiceAnswer:
        """The answer so far, typed; without one, why."""
        if self.response is not None:
            return ServiceAnswer(self.name, self.response)
        why = "no server" if self.future is None else "no answer"
        return ServiceAnswer(self.name, None, f"{why} on {self.name}")

    def close(self) -> None:
        self.node.destroy_client(self.client)


def call_service(node: Node, kind: Any, name: str, request: Any, timeout: float,
                 spin: Callable[[float], None] | None = None) -> ServiceAnswer:
    """Call ``name`` (waiting for its server) and wait for the answer, ``timeout`` seconds in
    all; ``spin(seconds)`` spins the node (default: ``rclpy.spin_once`` on it)."""
    if spin is None:
        import rclpy

        def spin(seconds: float) -> None:
            rclpy.spin_once(node, timeout_sec=seconds)

    call = ServiceCall(node, kind, name, request)
    deadline = time.monotonic() + timeout
    try:
        while not call.poll() and time.monotonic() < deadline:
            spin(min(0.05, max(0.0, deadline - time.monotonic())))
        return call.answer()
    finally:
        call.close()
