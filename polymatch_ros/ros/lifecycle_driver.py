"""The runner's side of the managed agents: it drives each agent process's lifecycle node
through ``configure`` and ``activate`` (``lifecycle_msgs/srv/ChangeState``), as
``ros2 lifecycle set`` would, without blocking its loop."""

from ..core.errors import PolymatchError


class LifecycleDriver:
    """``step()`` once per loop: configure every agent node whose service is up, activate each
    one that configured; a refused transition is an error naming the node."""

    def __init__(self, node, namespace, names, last_words=lambda name: ""):
        from lifecycle_msgs.msg import Transition
        from lifecycle_msgs.srv import ChangeState

        self.node, self.last_words = node, last_words
        self.steps = (Transition.TRANSITION_CONFIGURE, Transition.TRANSITION_ACTIVATE)
        self.labels = dict(zip(self.steps, ("configure", "activate")))
        self.clients = {
            name: node.create_client(ChangeState, f"{namespace.rstrip('/')}/{name}/change_state")
            for name in names
        }
        self.done = {name: 0 for name in names}  # transitions that succeeded, per node
        self.pending = {}  # name -> (transition, future)

    def active(self):
        return all(n == len(self.steps) for n in self.done.values())

    def step(self):
        """Send what is due, take what was answered; raise on a refused transition."""
        for name, client in list(self.clients.items()):
            if name in self.pending:
                self._take(name)
            elif self.done[name] < len(self.steps) and client.service_is_ready():
                self._send(name, client)
        if self.active() and self.clients:
            for client in self.clients.values():
                self.node.destroy_client(client)
            self.clients = {}

    def _send(self, name, client):
        transition = self.steps[self.done[name]]
        request = client.srv_type.Request()
        request.transition.id = transition
        self.pending[name] = (transition, client.call_async(request))

    def _take(self, name):
        transition, future = self.pending[name]
        if not future.done():
            return
        del self.pending[name]
        if not future.result().success:
            raise PolymatchError(
                f"{name}: lifecycle transition '{self.labels[transition]}' refused: "
                f"{self.last_words(name) or 'see its log'}"
            )
        self.done[name] += 1
