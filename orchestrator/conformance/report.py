"""A role's verdicts over all its vectors on one target, as a table or as JSON."""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import List

from orchestrator.conformance.judges import Verdict


@dataclass
class RoleReport:
    role: str
    target: str
    model_identifier: str
    verdicts: List[Verdict]

    @property
    def passed(self) -> bool:
        return all(v.passed for v in self.verdicts)

    def failed_vectors(self) -> List[str]:
        return sorted({v.vector for v in self.verdicts if not v.passed})


def format_table(report: RoleReport) -> str:
    header = ("vector", "check", "measured", "bound", "result")
    rows = []
    for v in report.verdicts:
        measured = "never" if v.measured == math.inf else ("—" if math.isnan(v.measured) else f"{v.measured:.4g}")
        rows.append((v.vector, v.check, f"{measured} {v.unit}".strip(), f"{v.bound} {v.unit}".strip(),
                     "pass" if v.passed else "FAIL"))
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]
    lines = ["  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip() for row in [header, *rows]]
    lines.insert(1, "  ".join("-" * w for w in widths))
    for v in report.verdicts:
        if not v.passed and v.note:
            lines.append(f"{v.vector}: {v.note}")
    failed = report.failed_vectors()
    total = len({v.vector for v in report.verdicts})
    lines.append(f"{report.role} on {report.target} ({report.model_identifier}): "
                 + (f"all {total} vectors pass" if not failed else
                    f"{len(failed)} of {total} vectors fail: {', '.join(failed)}"))
    return "\n".join(lines)


def format_json(report: RoleReport) -> str:
    return json.dumps({"role": report.role, "target": report.target, "model_identifier": report.model_identifier,
                       "passed": report.passed, "failed_vectors": report.failed_vectors(),
                       "checks": [v.as_dict() for v in report.verdicts]}, indent=1, ensure_ascii=False)
