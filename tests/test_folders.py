"""Files replaced whole (orchestrator/folders.py ``replacing``, the product's one
write-beside-then-rename): a reader sees the old file or the new one; a writer that fails leaves
the old one and nothing beside it; writers that may race each get a file of their own."""
import os

import pytest

from orchestrator.folders import replace_file, replacing


def test_a_file_is_replaced_whole_or_not_at_all(tmp_path):
    path = tmp_path / "summary.json"
    path.write_text("old")
    with pytest.raises(RuntimeError):
        with replacing(path) as handle:
            handle.write("half of the new")
            raise RuntimeError("the writer failed")
    assert path.read_text() == "old" and os.listdir(tmp_path) == ["summary.json"]
    replace_file(path, "new, in text")
    assert path.read_text() == "new, in text"
    replace_file(path, b"new, in bytes")
    assert path.read_bytes() == b"new, in bytes" and os.listdir(tmp_path) == ["summary.json"]


def test_a_link_at_the_name_beside_is_replaced_never_followed(tmp_path):
    victim = tmp_path / "victim"
    victim.write_text("untouched")
    folder = tmp_path / "out"
    folder.mkdir()
    (folder / ".metadata.json.tmp").symlink_to(victim)
    replace_file(folder / "metadata.json", "{}\n")
    assert victim.read_text() == "untouched"
    assert os.listdir(folder) == ["metadata.json"] and (folder / "metadata.json").read_text() == "{}\n"


def test_writers_that_may_race_never_rename_each_others_file(tmp_path):
    """Two at once (two installed runs refreshing a shipped system, two packers): each writes a
    file of its own beside the target, so each rename puts a whole file in place (the last one
    stays); with the one name beside, the first would have renamed the second's file."""
    path = tmp_path / "free_run.ssp"
    with replacing(path, binary=True, concurrent=True) as first:
        first.write(b"first, ")
        with replacing(path, binary=True, concurrent=True) as second:
            second.write(b"second, whole")
        assert path.read_bytes() == b"second, whole"
        first.write(b"whole")
    assert path.read_bytes() == b"first, whole" and os.listdir(tmp_path) == ["free_run.ssp"]
