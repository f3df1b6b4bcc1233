"""The options of a run across hosts: --only names agents (and describes them back), bad
--only and --discovery values are one line and exit code 2."""

import os
import subprocess
import sys

import pytest

from polymatch_ros.core.errors import ParameterError
from polymatch_ros.ros.supervisor.children import describe_agents, parse_only

# -- --only --------------------------------------------------------------------------------------

@pytest.mark.parametrize("text,n,expected", [
    ("0-7,12", 16, [0, 1, 2, 3, 4, 5, 6, 7, 12]),
    (" 3 ", 4, [3]),
    ("0-3,2-5", 8, [0, 1, 2, 3, 4, 5]),
    ("11, 0 - 1", 12, [0, 1, 11]),
    ("5-5", 6, [5]),
])
def test_only_names_agents(text, n, expected):
    assert parse_only(text, n) == expected
    assert parse_only(describe_agents(expected), n) == expected


@pytest.mark.parametrize("text,words", [
    ("", "e.g. --only 0-7,12"), ("a", "e.g."), ("1-", "e.g."), ("-1", "e.g."),
    ("0,,2", "e.g."), ("0-2-4", "e.g."), ("\u0663", "e.g."), ("1.5", "e.g."),
    ("3-1", "runs backwards"), ("0-12", "agent 12 is not in 0..11"), ("99", "not in 0..11"),
])
def test_malformed_or_out_of_range_only_is_one_line(text, words):
    with pytest.raises(ParameterError) as raised:
        parse_only(text, 12)
    assert words in str(raised.value) and "\n" not in str(raised.value)


def test_describe_agents():
    assert describe_agents([0, 1, 2, 3, 12]) == "0-3,12"
    assert describe_agents([4]) == "4"
    assert describe_agents([]) == ""


def _cli(*argv, env=None):
    return subprocess.run([sys.executable, "-m", "polymatch_ros.cli", "run"] + list(argv),
                          capture_output=True, text=True, timeout=60, env=env,
                          stdin=subprocess.DEVNULL)


@pytest.mark.parametrize("argv,words", [
    (["--only", "0-8"], "agent 8 is not in 0..7"),
    (["--only", "x"], "--only 'x'"),
    (["--only", "0-3"], "set the same ROS_DOMAIN_ID on every host"),
    (["--discovery", "multicast"], "the kind must be one of"),
    (["--discovery", "server:127.0.0.1:0"], "port '0'"),
])
def test_bad_host_options_exit_2_with_one_line(argv, words):
    env = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"}
    out = _cli("congruent_triangles", *argv, env=env)
    assert out.returncode == 2, out.stderr
    assert out.stderr.startswith("polymatch: error: ") and words in out.stderr, out.stderr
    assert len(out.stderr.strip().splitlines()) == 1 and "Traceback" not in out.stderr
