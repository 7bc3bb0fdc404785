"""A run's BLAS libraries run with `ProcessPolicy.blas_threads` threads (one by default), also a
library an FMU loads while the run makes its components (orchestrator/process_policy.py
`ProcessPolicy.blas_limited`): two threads would only spin on the cores' small matrices and, summing
in another order, change results in their last digit."""
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="one core: BLAS would use one thread anyway")
def test_a_blas_library_loaded_during_the_run_is_limited_too():
    script = textwrap.dedent("""
        import json, os, sys, tempfile
        from pathlib import Path
        from threadpoolctl import threadpool_info
        from orchestrator.verdicts.verdict import railway_verdicts
        from orchestrator.packaging.builder import default_build_dir
        from orchestrator.process_policy import BLAS_THREAD_VARIABLES
        from orchestrator.run import RunOptions, run_system
        assert 'scipy.linalg' not in sys.modules       # scipy's OpenBLAS comes with the rail line
        blas = lambda: {i['filepath']: i['num_threads'] for i in threadpool_info() if i['user_api'] == 'blas'}
        loaded = blas()
        before = {name: os.environ.get(name) for name in BLAS_THREAD_VARIABLES}
        with tempfile.TemporaryDirectory() as folder:
            run_system(Path('ssp/free_run'), RunOptions(summaries=railway_verdicts, stop_time=0.05,
                       output_dir=Path(folder), in_process=True, fmu_dirs=[default_build_dir()]))
        assert 'scipy.linalg' in sys.modules
        assert {name: os.environ.get(name) for name in BLAS_THREAD_VARIABLES} == before
        print(json.dumps({path: threads for path, threads in blas().items() if path not in loaded}))
    """)
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    done = subprocess.run([sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True, env=env)
    assert done.returncode == 0, done.stderr[-3000:]
    loaded_during_run = json.loads(done.stdout.strip().splitlines()[-1])      # file: threads
    if not loaded_during_run:
        pytest.skip("numpy and scipy share one BLAS library here: none is loaded during the run")
    assert set(loaded_during_run.values()) == {1}, loaded_during_run
