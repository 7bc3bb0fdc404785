"""Deliberately broken variants of our product facades, each with one behaviour broken, for
the conformance tests (tests/test_conform.py): `railcosim conform` must fail them and name the
vectors that catch the fault."""
from fmus.ato_controller.facade import AtoController
from fmus.loco_receiver.facade import LocoReceiver
from fmus.wayside_coder.facade import WaysideCoder

_LATCHED = ("aspect", "code_valid", "free_blocks", "v_permitted", "v_target")


class StuckReceiver(LocoReceiver):
    """A receiver whose display latches: it shows the first code it decodes forever."""

    _latched = None

    def step_core(self, current_time, step_size):
        super().step_core(current_time, step_size)
        io = self.io
        if self._latched is None and bool(io["code_valid"]):
            self._latched = {name: io[name].copy() for name in _LATCHED}
        if self._latched is not None:
            for name, value in self._latched.items():
                io[name][...] = value


class NoFailoverCoder(WaysideCoder):
    """A coder without its 2-out-of-2: a failed transmitter goes unreported and a failure of
    both leaves the code running."""

    def step_core(self, current_time, step_size):
        io = self.io
        io["fault_main"][...] = False
        io["fault_reserve"][...] = False
        super().step_core(current_time, step_size)


class BlindAto(AtoController):
    """An ATO/ATP that reads every cab code as green: it drives through a signal at danger."""

    def step_core(self, current_time, step_size):
        self.io["aspect"][...] = 4
        super().step_core(current_time, step_size)
