"""Test FMUs: a step counter, a gain with units, and a frame source / frame filter stage.

They exercise the master (rates, ordering, latency, frame semantics) and the SSP loader
(bindings, mappings, transformations) without any railway model.
"""
import math

import numpy as np
from scipy.signal import lfilter

from pythonfmu.default_experiment import DefaultExperiment

from fmus.fmi.slave import FacadeSlave, Port


class TestCounter(FacadeSlave):
    """Counts its own steps; echoes its input; reports the end time of its last step."""

    @classmethod
    def declare_ports(cls, build):
        return [
            Port("u", "input", unit="s"),
            Port("steps", "output", "Integer", start=0),
            Port("t_end", "output", unit="s"),
            Port("u_seen", "output", unit="s"),
            Port("fail_at", "parameter", unit="s", start=-1.0,
                 description="fail the step that starts at or after this time (negative: never)"),
        ]

    def create_core(self):
        return {"steps": 0}

    def step_core(self, t, h):
        fail_at = self.param("fail_at")
        if 0 <= fail_at <= t:
            raise RuntimeError(f"requested failure at t={t}")
        self.core["steps"] += 1
        self.io["steps"][...] = self.core["steps"]
        self.io["t_end"][...] = t + h
        self.io["u_seen"][...] = self.io["u"]


class TestGain(FacadeSlave):
    """y = k·u + bias, with units on every port (unit conversion tests)."""

    @classmethod
    def declare_ports(cls, build):
        return [
            Port("u", "input", unit="m/s"),
            Port("y", "output", unit="m/s"),
            Port("k", "parameter", unit="1", start=1.0),
            Port("bias", "parameter", unit="m/s", start=0.0),
            Port("enabled", "parameter", "Boolean", start=True),
            Port("mode", "parameter", "Integer", start=0),
            Port("label", "parameter", "String", start="none"),
            Port("mode_out", "output", "Integer", start=0),
            Port("enabled_out", "output", "Boolean", start=False),
        ]

    def create_core(self):
        return None

    def publish_initial_outputs(self):
        self.io["mode_out"][...] = self.param("mode")
        self.io["enabled_out"][...] = self.param("enabled")

    def step_core(self, t, h):
        gain = self.param("k") if self.param("enabled") else 0.0
        self.io["y"][...] = gain * self.io["u"] + self.param("bias")


class _FrameUnit(FacadeSlave):
    @classmethod
    def sample_rate_port(cls):
        return Port("fs", "parameter", unit="Hz", start=4000.0)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.required_step_s = self.build.frame / 4000.0

    def make_default_experiment(self):
        return DefaultExperiment(step_size=self.build.frame / 4000.0)

    def create_core(self):
        self.required_step_s = self.build.frame / self.param("fs")
        return self.make_core()


class TestFrameSource(_FrameUnit):
    """y[n] = the global sample number of sample n (value at t + (n-1)/fs)."""

    @classmethod
    def declare_ports(cls, build):
        return [cls.sample_rate_port(),
                Port("y", "output", shape=(build.frame,), frame=True, unit="1")]

    def make_core(self):
        return {"offsets": np.arange(self.build.frame, dtype=float)}

    def step_core(self, t, h):
        self.io["y"][:] = np.round(t * self.param("fs")) + self.core["offsets"]


class TestFrameStage(_FrameUnit):
    """First-order low-pass y = (1-a)·u + a·y[-1], state carried across frames (a = 0: wire)."""

    @classmethod
    def declare_ports(cls, build):
        return [cls.sample_rate_port(),
                Port("alpha", "parameter", start=0.0, min=0.0, max=0.999),
                Port("u", "input", shape=(build.frame,), frame=True, unit="1"),
                Port("y", "output", shape=(build.frame,), frame=True, unit="1")]

    def make_core(self):
        a = self.param("alpha")
        return {"b": np.array([1.0 - a]), "a": np.array([1.0, -a]), "zi": np.zeros(1)}

    def step_core(self, t, h):
        core = self.core
        self.io["y"][:], core["zi"] = lfilter(core["b"], core["a"], self.io["u"], zi=core["zi"])


class TestSchedule(FacadeSlave):
    """A timed command: ``schedule`` = "t0:value0;t1:value1;…" (seconds), held between entries."""

    @classmethod
    def declare_ports(cls, build):
        return [Port("schedule", "parameter", "String", start="0:0"),
                Port("command", "output", unit="1")]

    def create_core(self):
        pairs = [item.split(":") for item in self.param("schedule").split(";") if item.strip()]
        return sorted((float(t), float(v)) for t, v in pairs)

    def publish_initial_outputs(self):
        self.io["command"][...] = self._value(0.0)

    def _value(self, time_s):
        value = 0.0
        for start, v in self.core:
            if start <= time_s + 1e-9:
                value = v
        return value

    def step_core(self, t, h):
        # Gauss-Seidel hands this to consumers stepping over [t, t+h): the value in force at t
        self.io["command"][...] = self._value(t)


class TestSine(FacadeSlave):
    """The DCP reference implementation's example slave as an FMU: y = sin(k + a) after step k
    (k = 0, 1, …, counted before the step, whatever its length), y = sin(a) at initialisation;
    input a starts at 10. tests/test_dcp_interop.py serves it with that example's description."""

    @classmethod
    def declare_ports(cls, build):
        return [Port("y", "output", unit="1"),
                Port("a", "input", unit="1", start=10.0)]

    def make_default_experiment(self):
        return DefaultExperiment(step_size=0.01)

    def create_core(self):
        return {"steps": 0}

    def publish_initial_outputs(self):
        self.io["y"][...] = math.sin(float(self.io["a"]))

    def step_core(self, t, h):
        self.io["y"][...] = math.sin(self.core["steps"] + float(self.io["a"]))
        self.core["steps"] += 1
