"""`ruff check` over the product, the harness, the benchmarks and the tests finds nothing: the
rule set in pyproject.toml ([tool.ruff]), why it is that one: docs/architecture.md
("Dependencies")."""
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def test_ruff_finds_nothing():
    done = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", "--output-format", "concise"],
                          cwd=REPO, capture_output=True, text=True)
    assert "No module named ruff" not in done.stderr, "ruff is in the test extra: pip install -e '.[test]'"
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]
