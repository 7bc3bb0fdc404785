"""Write the conformance vectors (data/<role>.json and .npz) from our model cores and the
documented bounds: ``python -m orchestrator.conformance.generate [ROLE ...]``.

Every input is computed here (the coder core's transmitter output for the receiver, seeded
noise, the traction core for the expected motion), every bound is the one the unit's page
states (docs/loco_receiver.md, docs/digital_channels.md, docs/wayside_coder.md,
docs/rail_line.md, docs/traction.md, docs/ato.md); running this again writes the same files.
One module per role (its vectors), ``coder_signals.py`` the coder output several roles' vectors
are made of, ``role_file.py`` the file being written.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import List

from orchestrator.conformance import ROLES
from orchestrator.conformance.generate.ato_controller import ato_vectors
from orchestrator.conformance.generate.loco_receiver import receiver_vectors
from orchestrator.conformance.generate.rail_line import rail_vectors
from orchestrator.conformance.generate.role_file import GENERATOR
from orchestrator.conformance.generate.traction import traction_vectors
from orchestrator.conformance.generate.wayside_coder import coder_vectors
from orchestrator.conformance.vectors import DATA_DIR

GENERATORS = {"loco_receiver": receiver_vectors, "wayside_coder": coder_vectors, "rail_line": rail_vectors,
              "traction": traction_vectors, "ato_controller": ato_vectors}


def generate(roles=ROLES, directory: Path = DATA_DIR) -> List[Path]:
    """Write the vector files of ``roles`` into ``directory``; the paths written."""
    written = []
    for role in roles:
        written += GENERATORS[role]().write(directory)
    return written


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog=GENERATOR, description=__doc__.splitlines()[0])
    parser.add_argument("roles", nargs="*", help=f"roles (default all: {', '.join(GENERATORS)})")
    parser.add_argument("--dest", type=Path, default=DATA_DIR, help="folder (default: the package's data/)")
    args = parser.parse_args(argv)
    unknown = [r for r in args.roles if r not in GENERATORS]
    if unknown:
        print(f"{GENERATOR}: error: unknown role {', '.join(unknown)} (roles: {', '.join(GENERATORS)})", file=sys.stderr)
        return 2
    for path in generate(args.roles or list(GENERATORS), args.dest):
        print(f"wrote {path}")
    return 0
