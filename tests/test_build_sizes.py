"""FMUs of other build sizes beside the default ones (docs/architecture.md#build-sizes): a
system names them by a folder in its component sources, the build folder keeps them there."""
from fmus.sizes import BuildConfig, sizes_of_source
from orchestrator.systems.chain import committed_ports
from orchestrator.ssp import in_build_folder


def test_a_source_names_its_build_sizes_by_its_folder():
    assert sizes_of_source("resources/k32m2n120/RailLine.fmu") == BuildConfig(32, 2, 120)
    assert sizes_of_source("resources/RailLine.fmu") is None
    assert sizes_of_source("resources/k32x/RailLine.fmu") is None
    assert BuildConfig().folder_name == "" and BuildConfig(32, 2, 120).folder_name == "k32m2n120"


def test_a_build_folder_keeps_a_sized_fmu_in_its_own_folder():
    assert in_build_folder("resources/k32m2n120/RailLine.fmu") == "k32m2n120/RailLine.fmu"
    assert in_build_folder("resources/RailLine.fmu") == "RailLine.fmu"
    assert in_build_folder("RailLine.fmu") == "RailLine.fmu"


def test_the_committed_ports_take_the_sizes_of_the_source():
    default = committed_ports(None, "resources/RailLine.fmu")
    sized = committed_ports(None, "resources/k32m2n120/RailLine.fmu")
    assert default["u_tx"]["shape"] == [8, 40] and sized["u_tx"]["shape"] == [32, 120]
    assert sized["e_coil"]["shape"] == [2, 120] and sized["occupied"]["shape"] == [32]
    assert committed_ports(None, "resources/k32m2n120/LocoReceiver.fmu")["e_coil"]["shape"] == [120]


def test_a_system_naming_other_sizes_gets_them_built_and_resolved(tmp_path):
    from orchestrator.systems.chain import write_ssd
    from orchestrator.packaging.builder import build_sized_for
    from orchestrator.sspgen import ComponentSpec
    from orchestrator.ssp import open_system

    folder = tmp_path / "wide"
    write_ssd(folder, "wide", [ComponentSpec("rail", "resources/k12m2n40/RailLine.fmu", 0.01, {})], [], stop_time=0.1)
    builds = tmp_path / "fmus"
    results = build_sized_for(builds, [folder])
    assert [r.path for r in results] == [builds / "k12m2n40" / "RailLine.fmu"]
    system = open_system(folder, [builds])
    rail = system.components["rail"]
    assert rail.fmu_path == builds / "k12m2n40" / "RailLine.fmu"
    from fmpy import read_model_description

    names = {v.name for v in read_model_description(str(rail.fmu_path)).modelVariables}
    assert "u_tx[12,40]" in names and "u_tx[13,1]" not in names
