"""The runner's side of the managed agents: it drives each agent process's lifecycle node
to ``active`` (``lifecycle_msgs/srv/GetState`` and ``ChangeState``), as ``ros2 lifecycle set``
would, without blocking its loop.

A service answer can be lost: a server may answer before its reply writer has matched the
client's reader (rclpy then only warns "failed to send response"), although the client already
sees the service as ready.  So the driver asks each node for its state and sends the one
transition that state calls for (unconfigured: configure; inactive: activate); a question or
transition without an answer within ``RETRY_SECONDS`` is dropped and the state asked again.
A transition refused in its answer is an error naming the process.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any

from ...core.errors import PolymatchError

if TYPE_CHECKING:
    from rclpy.node import Node

RETRY_SECONDS: float = 2.0


class LifecycleDriver:
    """``step()`` once per loop until ``active()``: every agent node configured and active."""

    node: Node                               # the node the clients live on
    last_words: Callable[[str], str]
    next_transition: dict[int, tuple[int, str]]
    active_id: int
    finalized_id: int
    clients: dict[str, tuple[Any, Any]]      # name -> (GetState client, ChangeState client)
    done: set[str]
    pending: dict[str, tuple[str | None, Any, Any, float]]

    def __init__(self, node: Node, namespace: str, names: Iterable[str],
                 last_words: Callable[[str], str] = lambda name: "") -> None:
        from lifecycle_msgs.msg import State, Transition
        from lifecycle_msgs.srv import ChangeState, GetState

        self.node, self.last_words = node, last_words
        base = namespace.rstrip("/")
        self.next_transition = {
            State.PRIMARY_STATE_UNCONFIGURED: (Transition.TRANSITION_CONFIGURE, "configure"),
            State.PRIMARY_STATE_INACTIVE: (Transition.TRANSITION_ACTIVATE, "activate"),
        }
        self.active_id = State.PRIMARY_STATE_ACTIVE
        self.finalized_id = State.PRIMARY_STATE_FINALIZED
        self.clients = {
            name: (node.create_client(GetState, f"{base}/{name}/get_state"),
                   node.create_client(ChangeState, f"{base}/{name}/change_state"))
            for name in names
        }
        self.done = set()
        self.pending = {}  # name -> (label or None for a state question, client, future, sent)

    def active(self) -> bool:
        return len(self.done) == len(self.clients) or not self.clients

    def step(self) -> None:
        """Take what was answered, drop what is overdue, ask what is due."""
        now = time.monotonic()
        for name, (get, _) in self.clients.items():
            if name in self.done:
                continue
            if name in self.pending:
                self._take(name, now)
            elif get.service_is_ready():
                self.pending[name] = (None, get, get.call_async(get.srv_type.Request()), now)
        if self.clients and len(self.done) == len(self.clients):
            for pair in self.clients.values():
                for client in pair:
                    self.node.destroy_client(client)
            self.clients = {}

    def _take(self, name: str, now: float) -> None:
        label, client, future, sent = self.pending[name]
        if not future.done():
            if now - sent > RETRY_SECONDS:  # the answer was lost: ask the state again
                client.remove_pending_request(future)
                del self.pending[name]
            return
        del self.pending[name]
        answer = future.result()
        if label is not None:  # a transition: on success the next question finds the new state
            if not answer.success:
                raise PolymatchError(
                    f"{name}: lifecycle transition '{label}' refused: "
                    f"{self.last_words(name) or 'see its log'}"
                )
            return
        self._advance(name, answer.current_state.id, now)

    def _advance(self, name: str, state: int, now: float) -> None:
        if state == self.active_id:
            self.done.add(name)
        elif state == self.finalized_id:
            raise PolymatchError(f"{name}: its lifecycle node was shut down before it ran")
        elif state in self.next_transition:
            transition, label = self.next_transition[state]
            change = self.clients[name][1]
            request = change.srv_type.Request()
            request.transition.id = transition
            self.pending[name] = (label, change, change.call_async(request), now)
