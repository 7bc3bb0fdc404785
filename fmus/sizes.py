"""Sizes fixed when an FMU is built (docs/interfaces.md: frames, sections, trains). No dependencies."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Dict

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
