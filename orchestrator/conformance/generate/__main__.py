"""``python -m orchestrator.conformance.generate [ROLE ...]``: write the conformance vectors."""
import sys

from orchestrator.conformance.generate import main

sys.exit(main())
