"""The shortcuts into numpy's, scipy's and fmpy's internals (fmus/library_shortcuts.py for the
cores, orchestrator/library_shortcuts.py for the engine) give the answers of the public ways
they stand for, on the inputs their callers pass them, and are taken on the release lines they
were checked against."""
import ctypes

import fmpy
import numpy as np
import pytest
import scipy
from scipy.signal import butter, lfilter, sosfilt

from fmus import library_shortcuts as shortcuts
from orchestrator import library_shortcuts as engine_shortcuts


def _line(version: str, parts: int = 2) -> str:
    return ".".join(version.split(".")[:parts])


def test_the_shortcuts_are_taken_on_the_versions_they_were_checked_against():
    """This machine runs the checked release lines, and there every shortcut is taken: an
    upgrade shows here (compare the shortcuts on it with the tests below, then name it in
    CHECKED_AGAINST), not as a silent slow-down."""
    installed = {"numpy": _line(np.__version__), "scipy": _line(scipy.__version__)}
    assert installed == shortcuts.CHECKED_AGAINST
    assert shortcuts.in_use() == {"count_nonzero": True, "interp": True, "linear_filter": True,
                                  "sections_filter": True}
    assert {"numpy": _line(np.__version__), "fmpy": fmpy.__version__} == engine_shortcuts.CHECKED_AGAINST
    assert engine_shortcuts.in_use() == {"count_nonzero": True, "raw_function": True, "ssp_schema": True,
                                         "fmi_headers": True}


def test_another_release_line_takes_the_public_functions(monkeypatch):
    """On a numpy or scipy line not checked, each name is the public function: an internal
    routine may keep its name and change its meaning."""
    import importlib

    monkeypatch.setattr(np, "__version__", "9.0.0")
    monkeypatch.setattr(scipy, "__version__", "9.0.0")
    try:
        other = importlib.reload(shortcuts)
        assert other.in_use() == {"count_nonzero": False, "interp": False, "linear_filter": False,
                                  "sections_filter": False}
        assert other.count_nonzero is np.count_nonzero and other.interp is np.interp
        b, a = butter(2, 0.1)
        y, _ = other.linear_filter(b, a, np.ones(8), -1, np.zeros(2))
        np.testing.assert_array_equal(y, lfilter(b, a, np.ones(8), zi=np.zeros(2))[0])
    finally:
        monkeypatch.undo()
        importlib.reload(shortcuts)
    assert shortcuts.in_use()["linear_filter"]


@pytest.mark.parametrize("size", [0, 1, 40, 320])
def test_count_nonzero_is_np_count_nonzero(size):
    rng = np.random.default_rng(size)
    for share in (0.0, 0.3, 1.0):
        flags = rng.random(size) < share
        assert shortcuts.count_nonzero(flags) == np.count_nonzero(flags)


def test_interp_is_np_interp_inside_beyond_and_at_the_nodes():
    rng = np.random.default_rng(3)
    xp = np.cumsum(rng.uniform(1.0, 50.0, 30))
    fp = np.log(rng.uniform(0.1, 2.0, 30))
    x = np.concatenate([rng.uniform(xp[0] - 100.0, xp[-1] + 100.0, 400), xp])
    np.testing.assert_array_equal(shortcuts.interp(x, xp, fp), np.interp(x, xp, fp))


@pytest.mark.parametrize("rows", [0, 3])
def test_linear_filter_is_lfilter_with_state(rows):
    b, a = butter(4, [0.01, 0.05], btype="band")
    rng = np.random.default_rng(rows)
    x = rng.standard_normal((rows, 400) if rows else 400)
    zi = rng.standard_normal((rows, a.size - 1) if rows else a.size - 1)
    y, zf = shortcuts.linear_filter(b, a, x, -1, zi.copy())
    y_public, zf_public = lfilter(b, a, x, axis=-1, zi=zi.copy())
    np.testing.assert_array_equal(y, y_public)
    np.testing.assert_array_equal(zf, zf_public)


@pytest.mark.parametrize("rows", [0, 3])
def test_sections_filter_is_sosfilt_with_state_and_leaves_its_arguments(rows):
    sos = butter(4, [0.01, 0.05], btype="band", output="sos")
    rng = np.random.default_rng(rows)
    x = rng.standard_normal((rows, 400) if rows else 400)
    zi = rng.standard_normal((rows, sos.shape[0], 2) if rows else (sos.shape[0], 2))
    x_before, zi_before = x.copy(), zi.copy()
    y, zf = shortcuts.sections_filter(sos, x, zi)
    y_fallback, zf_fallback = shortcuts.public_sections_filter(sos, x, zi)
    np.testing.assert_array_equal(y, y_fallback)
    np.testing.assert_array_equal(zf, zf_fallback)
    public_zi = np.moveaxis(zi, 1, 0) if rows else zi
    y_public, zf_public = sosfilt(sos, x, axis=-1, zi=public_zi)
    np.testing.assert_array_equal(y, y_public)
    np.testing.assert_array_equal(zf, np.moveaxis(zf_public, 0, 1) if rows else zf_public)
    np.testing.assert_array_equal(x, x_before)
    np.testing.assert_array_equal(zi, zi_before)


# ---- the engine's -------------------------------------------------------------------------------
@pytest.mark.parametrize("size", [0, 1, 40, 320])
def test_the_engines_count_nonzero_is_np_count_nonzero(size):
    rng = np.random.default_rng(size)
    for share in (0.0, 0.3, 1.0):
        flags = rng.random(size) < share
        assert engine_shortcuts.count_nonzero(flags) == np.count_nonzero(flags)


def test_ssp_schemas_and_fmi_headers_are_where_fmpy_keeps_them():
    from lxml import etree

    schema = etree.XMLSchema(file=str(engine_shortcuts.ssp_schema("SystemStructureDescription.xsd")))
    assert schema is not None
    assert (engine_shortcuts.fmi_headers() / "fmi2FunctionTypes.h").is_file()
    from orchestrator.errors import UserError
    with pytest.raises(UserError, match="no SSP schemas there"):
        engine_shortcuts.ssp_schema("NoSuchSchema.xsd")


def test_a_raw_fmi_function_returns_the_status_fmpys_wrapper_checks(product_fmus, tmp_path, monkeypatch):
    """The binary's own fmi2GetReal answers as fmpy's wrapper does, returning the status instead
    of raising; a pythonfmu-only export is found, an absent one is None."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    path = product_fmus / "Traction.fmu"
    description = read_model_description(str(path))
    unzipped = extract(str(path), str(tmp_path / "traction"))
    fmu = FMU2Slave(guid=description.guid, unzipDirectory=unzipped,
                    modelIdentifier=description.coSimulation.modelIdentifier, instanceName="traction")
    fmu.instantiate()
    try:
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        refs = [v.valueReference for v in description.modelVariables if v.type == "Real"][:5]
        vr = (ctypes.c_uint * len(refs))(*refs)
        raw, wrapped = (ctypes.c_double * len(refs))(), (ctypes.c_double * len(refs))()
        get = engine_shortcuts.raw_function(fmu, "fmi2GetReal")
        assert get is not fmu.fmi2GetReal
        assert get(ctypes.c_void_p(fmu.component), vr, ctypes.c_size_t(len(refs)), raw) == 0
        fmu.fmi2GetReal(fmu.component, vr, len(refs), wrapped)
        assert list(raw) == list(wrapped)
        assert engine_shortcuts.library_function(fmu, "fmi2GetReal") is not None
        assert engine_shortcuts.library_function(fmu, "noSuchExport") is None
        monkeypatch.setattr(fmpy, "__version__", "0.0.0")        # a fmpy not checked: its wrapper
        assert engine_shortcuts.raw_function(fmu, "fmi2GetReal") == fmu.fmi2GetReal
    finally:
        fmu.terminate()
        fmu.freeInstance()
