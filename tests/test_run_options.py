"""A run's options are checked when they are made (orchestrator/plan.py RunOptions, and the
process policy they carry, orchestrator/process_policy.py): a value no run could use is one
UserError naming the option, before any system is loaded; made, they stay as checked."""
import dataclasses
import math
from pathlib import Path

import pytest

from orchestrator.errors import UserError
from orchestrator.plan import RunOptions
from orchestrator.process_policy import ProcessPolicy


@pytest.mark.parametrize("fields, says", [
    ({"stop_time": math.nan}, "--stop-time nan: must be a finite number of seconds up to 1e+06"),
    ({"stop_time": 2e6}, "--stop-time 2000000.0: must be a finite number of seconds up to 1e+06"),
    ({"output_interval": math.inf}, "--output-interval inf: must be a finite number of seconds"),
    ({"output_interval": -0.1}, "--output-interval -0.1: must be positive"),
    ({"algorithm": "newton"}, "--algorithm newton: choose gauss-seidel or jacobi"),
    ({"real_time": 0.0}, "--real-time 0.0: must be a number from"),
    ({"captures": "rail.e_coil[1]@0:1"}, "RunOptions.captures 'rail.e_coil[1]@0:1': a list of them"),
    ({"fmu_dirs": Path("build/fmus")}, "RunOptions.fmu_dirs 'build/fmus': a list of them"),
])
def test_an_option_no_run_could_use_is_refused_when_made(fields, says):
    with pytest.raises(UserError) as refused:
        RunOptions(**fields)
    assert str(refused.value).startswith(says)


def test_options_once_made_stay_as_checked():
    options = RunOptions(stop_time=1.0, output_dir="out")
    assert options.output_dir == Path("out")
    with pytest.raises(dataclasses.FrozenInstanceError):
        options.stop_time = math.nan
    with pytest.raises(UserError, match="--stop-time nan"):
        dataclasses.replace(options, stop_time=math.nan)      # a changed copy is checked again


@pytest.mark.parametrize("threads", [0, -1, 1.5, True, "2"])
def test_a_blas_thread_count_below_one_or_not_whole_is_refused(threads):
    with pytest.raises(UserError, match=r"^blas_threads .*: must be a whole number of threads, at least 1"):
        ProcessPolicy(blas_threads=threads)
