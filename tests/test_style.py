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


def _tracked_text_files():
    run = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True)
    if run.returncode != 0:
        return []
    return [p for p in run.stdout.split() if p.endswith((".md", ".py", ".xml", ".json", ".csv"))]


def test_the_readme_and_the_docs_stay_readable():
    """The README is at most 250 lines, and no tracked text file exceeds 300 KB."""
    with open(os.path.join(ROOT, "README.md"), encoding="utf-8") as f:
        assert len(f.read().splitlines()) <= 250
    files = _tracked_text_files()
    if not files:
        return  # not a git checkout: nothing to list
    big = [(p, os.path.getsize(os.path.join(ROOT, p))) for p in files
           if os.path.exists(os.path.join(ROOT, p))
           and os.path.getsize(os.path.join(ROOT, p)) > 300_000]
    assert not big, big
