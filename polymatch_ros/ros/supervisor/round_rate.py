"""Lockstep rounds per second of a scene, measured in a short real run (`polymatch trade
--over-ros`).

In lockstep every integrator stage is one message round (``MethodInfo.rounds`` per step), so a
method's wall time per simulated second is rounds per step / dt / rounds per second.  The
rounds per second are measured here: the run `polymatch run SCENE --integrator M --dt DT
--t-end T --no-monitor --no-compare` would make (``runner.run`` on the plan
``plan.build_run_plan`` makes of those options, every agent process with loopback discovery),
long enough for
``rounds`` rounds, in a process of its own (``python -m`` this module): the runner hosts rclpy,
whose teardown is bounded by ending that process (``teardown.end_process``), never the caller.
The agents' run records (``wire.RunRecord.rounds_per_second``, counted after the first round,
which waits for the last peer to start) are the result.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import IO

from ...core.errors import PolymatchError
from ...core.stepping.integrators import METHODS
from ..wire import run_records
from .packing import PackingAsked, choose_packing

__all__ = ["DEFAULT_ROUNDS", "RoundRate", "estimate_seconds", "main", "measure_round_rate"]

DEFAULT_ROUNDS = 200
#: the measuring run's namespace: apart from an ensemble the user runs in the same domain
ENSEMBLE = "polymatch_trade"
#: fewer rounds than this give no rate (the first round waits for the last peer to start)
MIN_ROUNDS = 20
#: seconds to end the measuring process after its own timeout (its teardown is bounded)
GRACE_SECONDS = 30.0


@dataclass(frozen=True)
class RoundRate:
    """A measured lockstep run: its method and step, rounds, processes and round rate."""

    method: str
    dt: float
    rounds: int                 # rounds of the agent that made the most
    processes: int              # agent processes
    rounds_per_second: float    # mean over the agent processes
    slowest: float              # the slowest agent process's rate
    wall: float                 # seconds the measurement took, start-up included
    finished: bool              # every agent reached the run's end (else cut at its limit)

    def wall_per_simulated_second(self, rounds_per_step: int, dt: float) -> float:
        """Wall seconds a lockstep run takes per simulated second at this round rate."""
        return rounds_per_step / dt / self.rounds_per_second

    def to_dict(self) -> dict[str, float | int | str]:
        return asdict(self)


def _processes(n_agents: int) -> int:
    """Agent processes `polymatch run --no-monitor` starts in lockstep (its default packing)."""
    k = choose_packing(PackingAsked(None, monitor=False), n_agents,
                       localhost=True).agents_per_process
    return -(-n_agents // k)


def estimate_seconds(n_agents: int, rounds: int = DEFAULT_ROUNDS) -> float:
    """A generous estimate of the measurement's wall time: start-up of the processes (linear in
    their number, growing with the load per core) and their rounds (a round rate falling with
    the square of the processes: docs/bench/scaling.md and packing.md hold the measured rates
    the constants below stay above)."""
    procs = _processes(n_agents)
    load = os.getloadavg()[0] / (os.cpu_count() or 1)
    return 5.0 + (1.5 + 0.6 * load) * procs + rounds * procs ** 2 / 6000.0


def measure_round_rate(scene_path: str, method: str, dt: float,
                       rounds: int = DEFAULT_ROUNDS, timeout: float = 120.0) -> RoundRate:
    """Run the scene in lockstep for about ``rounds`` rounds; the agents' round rate.

    ``timeout`` bounds the run (the runner's own limit); its process is ended by its PID
    ``GRACE_SECONDS`` later at the latest.  PolymatchError when the run gives no rate.
    """
    per_step = METHODS[method].info.rounds
    t_run = max(1, math.ceil(rounds / per_step)) * dt
    with tempfile.TemporaryDirectory(prefix="polymatch_trade_") as tmp:
        records, log = os.path.join(tmp, "records.jsonl"), os.path.join(tmp, "run.log")
        argv = [sys.executable, "-m", __name__, scene_path, method, repr(dt), repr(t_run),
                repr(timeout), records]
        start = time.monotonic()
        with open(log, "w+", encoding="utf-8") as out:
            code = _bounded(argv, out, timeout + GRACE_SECONDS)
            out.seek(0)
            text = out.read().strip().splitlines()
        wall = time.monotonic() - start
        lines: Sequence[str] = []
        if os.path.exists(records):
            with open(records, encoding="utf-8") as fh:
                lines = fh.read().splitlines()
    # a run cut at its time limit still reports the rounds its agents made
    agents = [r for r in run_records(lines) if r.role == "agent" and r.rounds_per_second > 0
              and r.rounds >= MIN_ROUNDS]
    if not agents:
        last = text[-1] if text else "no output"
        raise PolymatchError(f"the lockstep measuring run ({method}, dt {dt:g}) gave no round "
                             f"rate (exit {code}): {last}")
    rates = [r.rounds_per_second for r in agents]
    finished = code in (0, 3) and all(r.finished for r in agents)
    return RoundRate(method, dt, max(r.rounds for r in agents), len(agents),
                     sum(rates) / len(rates), min(rates), wall, finished)


def _bounded(argv: list[str], out: IO[str], seconds: float) -> int:
    """Run ``argv`` (output to ``out``) for at most ``seconds``; end it by its PID after."""
    proc = subprocess.Popen(argv, stdout=out, stderr=subprocess.STDOUT,
                            stdin=subprocess.DEVNULL)
    try:
        return proc.wait(timeout=seconds)
    except subprocess.TimeoutExpired:
        return -1
    finally:
        if proc.poll() is None:
            proc.terminate()          # the runner stops its agents on SIGTERM
            try:
                proc.wait(timeout=GRACE_SECONDS)
            except subprocess.TimeoutExpired:
                proc.kill()
                with contextlib.suppress(subprocess.TimeoutExpired):
                    proc.wait(timeout=5)


def main(argv: Sequence[str] | None = None) -> None:
    """The measuring process: SCENE METHOD DT T_END TIMEOUT RUN_RECORDS; ends with the run's
    code."""
    from ..process.teardown import end_process
    from . import runner
    from .plan import RunOptions, build_run_plan

    p = argparse.ArgumentParser(prog="round_rate")
    for name in ("scene", "method"):
        p.add_argument(name)
    for name in ("dt", "t_end", "timeout"):
        p.add_argument(name, type=float)
    p.add_argument("run_records")
    args = p.parse_args(argv)
    code = 1
    try:
        # `polymatch run SCENE --integrator M --dt DT --t-end T --no-monitor --no-compare
        # --quiet`, with the records kept and no stop before t_end
        options = RunOptions(args.scene, integrator=args.method, dt=args.dt, t_end=args.t_end,
                             timeout=args.timeout, hold=1e9, ensemble=ENSEMBLE, monitor=False,
                             compare=False, quiet=True, run_records=args.run_records)
        code = runner.run(build_run_plan(options))
    except PolymatchError as exc:
        print(f"polymatch: error: {json.dumps(str(exc))[1:-1]}", file=sys.stderr)
        code = exc.exit_code
    end_process(code)


if __name__ == "__main__":
    main()
