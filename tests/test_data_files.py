"""One rule for a relative ``*_file`` parameter (docs/interfaces.md, SSP conventions, "Data
files"): the system's resources/ folder, then the system folder, else left for the FMU."""
from orchestrator.graph import resolve_data_file


def test_resources_first_then_the_system_folder_else_left_as_given(tmp_path):
    (tmp_path / "resources").mkdir()
    (tmp_path / "both.json").write_text("{}")
    (tmp_path / "resources" / "both.json").write_text("{}")
    (tmp_path / "top.json").write_text("{}")
    (tmp_path / "resources" / "sub").mkdir()
    (tmp_path / "resources" / "sub" / "deep.json").write_text("{}")
    assert resolve_data_file("both.json", tmp_path) == str((tmp_path / "resources" / "both.json").resolve())
    assert resolve_data_file("top.json", tmp_path) == str((tmp_path / "top.json").resolve())
    assert resolve_data_file("sub/deep.json", tmp_path) == str((tmp_path / "resources" / "sub" / "deep.json").resolve())
    assert resolve_data_file("resources/sub/deep.json", tmp_path) == \
        str((tmp_path / "resources" / "sub" / "deep.json").resolve())
    # not a file of the system: the FMU resolves it against its own resources
    assert resolve_data_file("default_line.json", tmp_path) == "default_line.json"
    assert resolve_data_file("sub", tmp_path) == "sub"                 # a folder is not a data file


def test_empty_and_absolute_values_are_left_alone(tmp_path):
    absolute = str(tmp_path / "elsewhere.json")
    assert resolve_data_file("", tmp_path) == ""
    assert resolve_data_file(absolute, tmp_path) == absolute
    assert resolve_data_file(None, tmp_path) is None
