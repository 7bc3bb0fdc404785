"""``railcosim --version``: the installed railcosim's version, as metadata.json records it."""
import re
from importlib import metadata

from helpers import railcosim


def test_version_prints_railcosim_and_its_version():
    code, stdout, stderr = railcosim("--version")
    assert code == 0 and stderr == "", stderr
    assert re.fullmatch(r"railcosim \d+\.\d+\.\d+\n", stdout), stdout
    assert stdout == f"railcosim {metadata.version('railcosim')}\n"
