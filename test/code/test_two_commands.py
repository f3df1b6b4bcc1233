"""README's first screen: the paper, the fastest way in without ROS, then the demo and the
tests, each command doing all set-up first; CI runs exactly the test command.  The demo's
set-up installs only what builds the interface package (cmake, g++); the test command installs the
multi-host tests' tools."""

import pathlib
import re
import subprocess

ROOT = pathlib.Path(__file__).resolve().parents[2]


def readme_setup_blocks():
    """The bash blocks of README's "Set up, run, test" section, as lists of lines."""
    text = (ROOT / "README.md").read_text()
    section = text.split("## Set up, run, test", 1)[1].split("\n## ", 1)[0]
    blocks = re.findall(r"```bash\n(.*?)```", section, re.S)
    return [[line for line in block.splitlines() if line.strip()] for block in blocks]


NO_ROS = ("bash scripts/setup.sh && .venv/bin/polymatch simulate congruent_triangles "
          "--figure fig1.png")


def test_readme_shows_no_ros_path_then_demo_then_tests():
    blocks = readme_setup_blocks()
    assert blocks[:3] == [[NO_ROS], ["bash scripts/demo.sh"], ["bash scripts/test.sh"]]
    later = "\n".join(line for block in blocks[3:] for line in block)
    assert "pip install" not in later and "venv .venv" not in later


def test_readme_first_screen_links_the_paper_and_says_what_each_command_prints():
    text = (ROOT / "README.md").read_text()
    first = text.split("## A short tour", 1)[0]
    assert "https://arxiv.org/abs/2006.11533" in "\n".join(first.splitlines()[:10])
    assert first.index(NO_ROS) < first.index("bash scripts/demo.sh") < \
        first.index("bash scripts/test.sh")
    for said in ("converged: matching", "about 2 s", "about a minute", "about 10 minutes"):
        assert said in first.replace("\n", " "), said
    for internal in ("slot", "priority", "repeat_tests", "20 times", "twenty times"):
        assert internal not in text, internal        # the testing page's business
    assert "docs/guide/testing.md" in first
    assert "testing.md" in (ROOT / "docs" / "guide" / "index.md").read_text()


def test_ci_runs_readme_test_command():
    lines = [line for line in (ROOT / ".ci" / "run").read_text().splitlines()
             if line.strip() and not line.startswith("#")]
    assert lines[-1] == "bash scripts/test.sh"


def test_both_commands_set_up_first_then_run():
    for name, runs in (("demo.sh", ".venv/bin/polymatch run config/congruent_triangles.yaml"),
                       ("test.sh", ".venv/bin/python -m pytest -q test")):
        body = (ROOT / "scripts" / name).read_text()
        assert body.index("bash scripts/setup.sh") < body.index(runs), name
    setup = (ROOT / "scripts" / "setup.sh").read_text()
    assert "install-system-packages.sh" in setup and "pip install" in setup


def test_demo_installs_only_the_interface_build_tools_and_tests_install_theirs():
    script = (ROOT / "scripts" / "install-system-packages.sh").read_text()
    assert "demo) wanted=(cmake g++) ;;" in script
    assert "test) wanted=(cmake g++ iproute2 nftables tcpdump) ;;" in script
    out = subprocess.run(["bash", str(ROOT / "scripts" / "install-system-packages.sh"), "demo"],
                         capture_output=True, text=True, timeout=900)
    assert out.returncode == 0 and out.stdout.startswith("system packages: "), out
    assert "nftables" not in out.stdout and "tcpdump" not in out.stdout, out
    test_sh = (ROOT / "scripts" / "test.sh").read_text()
    assert "bash scripts/install-system-packages.sh test" in test_sh
    assert "nftables" not in (ROOT / "scripts" / "demo.sh").read_text()
    setup = (ROOT / "scripts" / "setup.sh").read_text()
    assert "install-system-packages.sh test" not in setup


def test_scripts_parse():
    for script in sorted((ROOT / "scripts").glob("*.sh")):
        assert subprocess.run(["bash", "-n", str(script)], capture_output=True).returncode == 0
