"""README's set-up is two commands, each doing all set-up first: one runs the main demo, one
the whole suite, and CI runs exactly the second."""

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


def test_readme_sets_up_with_two_commands_demo_and_tests():
    blocks = readme_setup_blocks()
    assert blocks[:2] == [["bash scripts/demo.sh"], ["bash scripts/test.sh"]]
    later = "\n".join(line for block in blocks[2:] for line in block)
    assert "pip install" not in later and "venv .venv" not in later


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


def test_scripts_parse():
    for script in sorted((ROOT / "scripts").glob("*.sh")):
        assert subprocess.run(["bash", "-n", str(script)], capture_output=True).returncode == 0
