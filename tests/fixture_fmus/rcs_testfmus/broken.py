"""Deliberately broken variants of our product facades, each with one behaviour broken, for
the conformance tests (tests/test_conform.py): `railcosim conform` must fail them and name the
vectors that catch the fault."""
from fmus.ato_controller.facade import AtoController
from fmus.loco_receiver.facade import LocoReceiver
from fmus.loco_receiver.tvm430 import Tvm430ReceiverCore
from fmus.signalling import tvm430
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


class _UncheckedTvm430(tvm430.Tvm430System):
    """TVM-430 word tables read without the check: any 27 bits with a known address, speed and
    distance mean something."""

    def reading(self, word):
        data = word >> tvm430.FIELDS["check"][1]
        return super().reading((data << tvm430.FIELDS["check"][1]) | tvm430.check_bits(data))


class UncheckedTvmReceiver(LocoReceiver):
    """A TVM-430 receiver that ignores the word's check bits: a corrupted word whose fields
    still mean something is shown."""

    def create_core(self):
        core = super().create_core()
        if isinstance(core, Tvm430ReceiverCore):
            core.tvm = _UncheckedTvm430(core.tvm.table)
        return core


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
