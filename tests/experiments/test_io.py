import pytest
import torch

from hubsgo_ppl.experiments.io import (CheckpointError, atomic_write, load_checkpoint, save_torch,
                                       write_json)


def test_atomic_write_keeps_old_file_when_writer_fails(tmp_path):
    path = tmp_path / "a.json"
    write_json(path, {"v": 1})

    def boom(fh):
        fh.write("partial")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError):
        atomic_write(path, boom, mode="w")
    assert path.read_text().strip().startswith("{")
    assert '"v": 1' in path.read_text()
    assert [p.name for p in tmp_path.iterdir()] == ["a.json"]   # no temp file left behind


def test_checkpoint_roundtrip_and_clear_errors(tmp_path):
    save_torch(tmp_path / "c.pt", {"format": 1, "x": torch.arange(3)})
    assert load_checkpoint(tmp_path / "c.pt")["x"].tolist() == [0, 1, 2]
    with pytest.raises(CheckpointError, match="no checkpoint here"):
        load_checkpoint(tmp_path / "missing.pt")
    (tmp_path / "bad.pt").write_bytes(b"\x00garbage" * 10)
    with pytest.raises(CheckpointError, match="corrupt"):
        load_checkpoint(tmp_path / "bad.pt")
    save_torch(tmp_path / "other.pt", {"weights": 1})
    with pytest.raises(CheckpointError, match="not a hubsgo checkpoint"):
        load_checkpoint(tmp_path / "other.pt")
