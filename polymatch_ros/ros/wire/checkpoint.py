"""A lockstep process's checkpoint: its local state at the start of its current step, on disk.

A lockstep trajectory is a pure function of the initial state and the rounds exchanged, so a
process that died resumes exactly if it restarts from the state it had at the start of a step
whose rounds its peers still hold (``stage_links``: they keep the last ``rounds + 2``).  The
process writes that state before it publishes the step's first round; a peer can be at most
one round into the next step before it needs this process's message again, so the step of the
last checkpoint written is always one the peers can still replay.

The state is written whole, with the mean field cached on it (``State.coupling``): an FSAL
method (``MethodInfo.rounds < stages``) takes a step's first evaluation from it, and a
process that evaluated it anew would exchange one round more than its peers.  With it go the
stage messages of the rounds this process keeps for resends: when two processes die close
together, one may resume a step before the other, and then needs the other's messages of
that step, which only the other had; restored from its checkpoint, they are sent again.
The files live in the runner's private temporary directory and are read by the process that
wrote them, restarted, and by the runner for the partial result of a run that ended early.
"""

from __future__ import annotations

import os
import pickle
import struct
import zlib
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ...core.model import State

#: the kept rounds of a lockstep process, as data: (turn, ((writer key: agent or block,
#: message data), ...)), ...
Kept = tuple[tuple[int, tuple[tuple[int, bytes], ...]], ...]

#: a slot's header: the payload's length and CRC-32
HEADER = struct.Struct("<QI")


@dataclass(frozen=True)
class Checkpoint:
    """The local state at the start of step ``step`` (0-based), at time ``t`` on the grid."""

    step: int
    t: float
    state: State
    run_id: int
    sent: Kept = ()   # lockstep: the stage messages of its last rounds (``stage_links``)


class CheckpointFile:
    """One process's checkpoint (``path``; '' for none): ``write`` each step, ``read`` once.

    Two slots (``path.0``, ``path.1``), written in turn in place (``os.pwrite``: no file is
    created, renamed or truncated per step, which cost a file-system round trip a step on a
    disk-backed /tmp), each a header (length, CRC-32) and the pickled ``Checkpoint``; ``read``
    takes the valid slot of the later step, so a process killed in the middle of a write leaves the
    other slot's step.
    """

    def __init__(self, path: str, run_id: int) -> None:
        self.path, self.run_id = path, int(run_id)
        self.written = 0
        self._fds: list[int] = []

    @property
    def enabled(self) -> bool:
        return bool(self.path)

    def write(self, step: int, t: float, state: State, sent: Kept = ()) -> None:
        """The state at the start of ``step`` (and the messages of the rounds before it that
        this process keeps), into the slot not holding the last one."""
        if not self.path:
            return
        if not self._fds:
            flags = os.O_RDWR | os.O_CREAT
            self._fds = [os.open(f"{self.path}.{slot}", flags, 0o600) for slot in (0, 1)]
        payload = pickle.dumps(Checkpoint(step, float(t), state, self.run_id, sent),
                               protocol=pickle.HIGHEST_PROTOCOL)
        header = HEADER.pack(len(payload), zlib.crc32(payload))
        os.pwrite(self._fds[self.written % 2], header + payload, 0)
        self.written += 1

    def read(self) -> Checkpoint | None:
        """The last whole checkpoint of this run, or None (none yet, or another run's)."""
        found = [c for c in map(self._slot, (0, 1)) if c is not None and c.run_id == self.run_id]
        return max(found, key=lambda c: c.step, default=None)

    def _slot(self, slot: int) -> Checkpoint | None:
        try:
            with open(f"{self.path}.{slot}", "rb") as fh:
                data = fh.read()
        except OSError:
            return None
        if len(data) < HEADER.size:
            return None
        length, crc = HEADER.unpack_from(data)
        payload = data[HEADER.size:HEADER.size + length]
        if len(payload) != length or zlib.crc32(payload) != crc:
            return None  # cut short by the process's death
        found = pickle.loads(payload)  # noqa: S301 - our own file, in the run's private directory
        return found if isinstance(found, Checkpoint) else None

    def close(self) -> None:
        for fd in self._fds:
            os.close(fd)
        self._fds = []
