"""Sizes fixed when an FMU is built (docs/interfaces.md: frames, sections, trains). No dependencies."""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import PurePosixPath
from typing import Dict, Optional

#: The signal chain's sample rate unless a system sets ``fs`` (10 ms frames of 40 samples;
#: docs/interfaces.md): the default of the coder, rail line and receiver settings and ports.
DEFAULT_SAMPLE_RATE_HZ = 4000.0


@dataclass(frozen=True)
class BuildConfig:
    """The build sizes of the signal-chain FMUs."""

    sections: int = 8   # K block sections
    trains: int = 2     # M trains
    frame: int = 40     # N samples per waveform frame

    def as_dict(self) -> Dict[str, int]:
        return {"sections": self.sections, "trains": self.trains, "frame": self.frame}

    @property
    def folder_name(self) -> str:
        """Where a build of these sizes lives inside a build folder, and the folder a system's
        component source names for it (``resources/k32m2n40/RailLine.fmu``); the default
        sizes live in the build folder itself (``resources/RailLine.fmu``)."""
        return "" if self == BuildConfig() else f"k{self.sections}m{self.trains}n{self.frame}"


_SIZED_FOLDER = re.compile(r"k(\d+)m(\d+)n(\d+)")


def sizes_of_source(source: str) -> Optional[BuildConfig]:
    """The build sizes a component source names by its folder (``…/k32m2n40/RailLine.fmu``),
    None for a source in no sized folder (the default build)."""
    match = _SIZED_FOLDER.fullmatch(PurePosixPath(source).parent.name)
    return BuildConfig(*(int(g) for g in match.groups())) if match else None

