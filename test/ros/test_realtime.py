"""Realtime mode: wall-clock agents with the latest peer poses converge, survive a killed peer,
and re-admit it when it comes back (Theorem 4.2 under delays and churn)."""

import re
import time

from ros_harness import PY, needs_ros, scene_path

pytestmark = needs_ros

SCENE = "congruent_triangles"
N = 8


def _heard(text):
    """(heard, diameter, below?) for every monitor diagnostics message printed so far."""
    out = []
    for m in re.finditer(
        r"matching diameter ([0-9.e+-]+) \((below|above) tolerance [^)]*\); (\d+)/8 agents heard",
        text,
    ):
        out.append((int(m.group(3)), float(m.group(1)), m.group(2) == "below"))
    return out


def _wait_for(ros, proc, predicate, timeout, unless_all_ended=()):
    """Poll the monitor's record until ``predicate`` holds; False after ``timeout`` s, or as soon
    as
    every process in ``unless_all_ended`` has exited without it holding."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        ended = unless_all_ended and all(p.poll() is not None for p in unless_all_ended)
        if predicate(_heard(ros.output(proc))):
            return True
        if ended:
            time.sleep(0.5)  # the monitor's last reports of the run
            return predicate(_heard(ros.output(proc)))
        time.sleep(0.2)
    return False


# 20 steps per wall-clock second: 8 agents, the monitor and an echo hold it on 2 loaded cores
# (measured while other test suites ran beside: few ticks late per agent, where at 50 Hz nearly
# every tick was late and the ensemble fell behind the wall clock)
RATE = 20.0
RUN_BOUND = 180  # s: only a hang takes this long; the run itself ends at t_end (simulated)


def test_realtime_default_packing_is_one_process_and_says_why(ros):
    """Without -k a realtime run packs its agents as measured (``supervisor.packing``): one
    process steps all eight together, each still its own node; its first line says why."""
    proc = ros.start(
        [PY, "-m", "polymatch_ros.cli", "run", scene_path(SCENE), "--mode", "realtime",
         "--rate", str(RATE), "--time-scale", "2", "--t-end", "2", "--timeout", "90", "-v"],
        timeout=120,
    )
    rc = ros.wait(proc, 130)
    text = ros.output(proc)
    assert rc in (0, 3), text
    assert re.search(r"^polymatch run: 8 agents in 1 process of up to 8, agent nodes full "
                     r"\(realtime's measured packing", text, re.M), text
    assert re.search(r"^agent 0,1,2,3,4,5,6,7: finished at t = 2 after 20 realtime steps", text,
                     re.M), text


def test_realtime_converges_survives_sigkill_and_rejoin_theorem_4_2(ros):
    start = time.time() + 10.0  # every process is up well before t = 0
    common = dict(
        mode="realtime", rate=RATE, time_scale=3.0, start_time=start, t_end=90.0, peer_timeout=1.0
    )
    ros.monitor(
        SCENE, timeout=RUN_BOUND + 20, mode="realtime", rate=5.0, peer_timeout=1.0, t_end=90.0
    )
    agents = [ros.agent(SCENE, i, timeout=RUN_BOUND + 20, **common) for i in range(N)]
    diag = ros.start(
        [PY, "-m", "polymatch_ros.cli", "echo", "/diagnostics", "--timeout", str(RUN_BOUND)],
        timeout=RUN_BOUND + 10,
    )

    # all eight run and are heard
    assert _wait_for(ros, diag, lambda h: any(n == 8 for n, _, _ in h), 25), ros.output(diag)[
        -2000:
    ]
    time.sleep(max(0.0, start + 3.0 - time.time()))  # t = 9: mid-run
    ros.kill(agents[5])  # SIGKILL, no goodbye
    marked = len(_heard(ros.output(diag)))
    # the monitor reports one agent fewer, and the others keep converging
    assert _wait_for(ros, diag, lambda h: any(n == 7 for n, _, _ in h[marked:]), 10), ros.output(
        diag
    )[-2000:]
    # three reports of the seven (0.6 s at the monitor's 5 Hz; longer on a loaded machine)
    assert _wait_for(ros, diag, lambda h: sum(n == 7 for n, _, _ in h[marked:]) >= 3, 30), (
        ros.output(diag)[-2000:]
    )
    seven = [d for n, d, _ in _heard(ros.output(diag))[marked:] if n == 7]
    assert seven[-1] < seven[0], seven
    assert all(a.poll() is None for i, a in enumerate(agents) if i != 5), (
        "the survivors keep running"
    )

    # restart agent 5: it rejoins (from its initial state, on the ensemble's clock) and matches
    # before the run ends at t_end - however long a loaded machine takes to get there
    marked = len(_heard(ros.output(diag)))
    agents[5] = ros.agent(SCENE, 5, timeout=RUN_BOUND + 20, **common)
    assert _wait_for(ros, diag, lambda h: any(n == 8 for n, _, _ in h[marked:]), 30, agents), (
        ros.output(diag)[-2000:]
    )
    assert _wait_for(
        ros, diag, lambda h: any(n == 8 and below for n, _, below in h[marked:]), RUN_BOUND, agents
    ), ros.output(diag)[-3000:] + "".join(ros.output(a)[-300:] for a in agents)


def test_last_realtime_progress_line_has_the_true_diameter_and_a_rate(ros):
    """Two processes of four agents (``-k 4``), each stepping its agents together and reading
    the other's states as one block a tick: the runner's last progress line is the final
    state's, its diameter is the summary's, its rate is not negative (a monitor report of
    fewer agents after the end must not count); each process reports its CPU time per tick,
    and the agents' diameter fell (Theorem 4.2: the ensemble matches)."""
    proc = ros.start(
        [
            PY,
            "-m",
            "polymatch_ros.cli",
            "run",
            scene_path(SCENE),
            "--mode",
            "realtime",
            "--rate",
            str(RATE),
            "--time-scale",
            "2",
            "--t-end",
            "6",
            "--timeout",
            "120",
            "-k",
            "4",
            "-v",
        ],
        timeout=150,
    )
    rc = ros.wait(proc, 160)
    text = ros.output(proc)
    assert re.search(r"^polymatch run: 8 agents in 2 processes of up to 4", text, re.M), text
    # each process's line (-v) gives its CPU time per tick, measured over its ticks
    cpu = re.findall(r"^agent ([0-9,]+): .*?(\d+) started more than one period late "
                     r"\(CPU ([0-9.]+) ms per tick\).*no messages dropped", text, re.M)
    assert sorted(a for a, _, _ in cpu) == ["0,1,2,3", "4,5,6,7"], text
    assert all(float(v) > 0.0 for _, _, v in cpu), text
    assert rc in (0, 3), text
    progress = re.findall(r"^t = +([0-9.]+) / .*diameter = (\S+) +(\S+) rounds/s", text, re.M)
    assert progress, text
    t, diameter, rate = (float(v) for v in progress[-1])
    summary = re.search(r"^triangles +8 +\S+ +\S+ +(\S+) ", text, re.M)
    assert summary and diameter == float(summary.group(1)), text
    assert diameter > 0.0 and rate >= 0.0 and t == 6.0, text
    first = float(progress[0][1])
    assert diameter < 0.5 * first, (first, diameter)
