"""The tree is clean under the project's ruff configuration (pyproject.toml)."""
import os
import shutil
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_ruff_finds_nothing():
    ruff = shutil.which("ruff", path=os.path.dirname(sys.executable)) or shutil.which("ruff")
    assert ruff, "ruff is not installed: pip install -e '.[test]'"
    run = subprocess.run([ruff, "check", "--no-cache", "--output-format", "concise", ROOT],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stdout + run.stderr
