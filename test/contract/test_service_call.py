"""One bounded service call (``wire.service_call``): sent once the server is up, sent again
when its answer is overdue, a typed answer or the one-line reason there is none.

Oracle: a scripted client that records every request and drop, and a fake clock."""

from polymatch_ros.ros.wire import service_call
from polymatch_ros.ros.wire.service_call import ServiceCall, call_service


class _Future:
    def __init__(self):
        self.value = None

    def done(self):
        return self.value is not None

    def result(self):
        return self.value


class _Client:
    """Ready after ``ready_after`` polls; answers the requests whose index is in ``answered``."""

    def __init__(self, ready_after=0, answered=(0,)):
        self.polls, self.ready_after, self.answered = 0, ready_after, set(answered)
        self.sent, self.dropped, self.destroyed = [], [], False

    def service_is_ready(self):
        self.polls += 1
        return self.polls > self.ready_after

    def call_async(self, request):
        future = _Future()
        if len(self.sent) in self.answered:
            future.value = ("answer to", request)
        self.sent.append(future)
        return future

    def remove_pending_request(self, future):
        self.dropped.append(future)


class _Node:
    def __init__(self, client):
        self.client = client

    def create_client(self, kind, name):
        return self.client

    def destroy_client(self, client):
        client.destroyed = True


def test_a_call_waits_for_its_server_then_returns_the_typed_answer(monkeypatch):
    client = _Client(ready_after=3)
    spins = []
    answer = call_service(_Node(client), object, "/x/start", "req", 5.0, spins.append)
    assert answer.answered and answer.response == ("answer to", "req")
    assert answer.name == "/x/start" and answer.failure == ""
    # three spins while the server is not up, one for the answer
    assert len(client.sent) == 1 and len(spins) == 4 and client.destroyed


def test_an_overdue_answer_is_asked_again_and_the_lost_request_dropped(monkeypatch):
    now = [0.0]
    monkeypatch.setattr(service_call.time, "monotonic", lambda: now[0])
    client = _Client(answered=(1,))            # the first answer is lost
    call = ServiceCall(_Node(client), object, "/x/set", "req", resend_after=2.0)
    assert not call.poll() and len(client.sent) == 1
    now[0] = 1.9
    assert not call.poll() and len(client.sent) == 1      # not yet overdue
    now[0] = 2.1
    assert not call.poll() and client.dropped == [client.sent[0]] and len(client.sent) == 2
    assert call.poll() and call.answer().response == ("answer to", "req")


def test_no_server_within_the_timeout_is_a_one_line_failure(monkeypatch):
    now = [0.0]
    monkeypatch.setattr(service_call.time, "monotonic", lambda: now[0])

    def spin(seconds):
        now[0] += 0.5

    client = _Client(ready_after=10**6)
    answer = call_service(_Node(client), object, "/x/stop", "req", 2.0, spin)
    assert not answer.answered and answer.response is None
    assert answer.failure == "no server on /x/stop" and client.sent == [] and client.destroyed
