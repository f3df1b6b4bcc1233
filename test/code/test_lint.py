"""The repository passes `ruff check` with its ruff.toml (line length 99, as ament_flake8)."""

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _ruff_command():
    """The venv's ruff executable, else `python -m ruff`; None if ruff is not installed."""
    exe = Path(sys.executable).with_name("ruff")
    if exe.exists():
        return [str(exe)]
    if importlib.util.find_spec("ruff") is not None:
        return [sys.executable, "-m", "ruff"]
    return None


def test_repository_passes_ruff_check():
    cmd = _ruff_command()
    if cmd is None:
        pytest.skip("ruff is not installed in this environment (pip install ruff)")
    res = subprocess.run(cmd + ["check", "--no-cache", "--config", str(ROOT / "ruff.toml"),
                                str(ROOT)],
                         capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert res.returncode == 0, f"ruff check found problems:\n{res.stdout}{res.stderr}"
