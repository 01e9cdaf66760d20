import os
import stat

import numpy as np
import pytest
import torch

from hubsgo_ppl.experiments.io import (CheckpointError, atomic_path, atomic_write, checkpoint_globals,
                                       is_temp_file, load_checkpoint, save_torch, truncate_csv, write_json)


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
    # a truncated file: the reason is torch's first sentence, whole, not cut inside a word
    good = (tmp_path / "c.pt").read_bytes()
    (tmp_path / "cut.pt").write_bytes(good[: len(good) // 2])
    with pytest.raises(CheckpointError) as err:
        load_checkpoint(tmp_path / "cut.pt")
    reason = str(err.value).split("(", 1)[1].rsplit(")", 1)[0]
    assert reason.endswith((".", "...")) and "If yo" not in reason and len(reason) < 160
    save_torch(tmp_path / "other.pt", {"weights": 1})
    with pytest.raises(CheckpointError, match="not a hubsgo checkpoint"):
        load_checkpoint(tmp_path / "other.pt")


@pytest.fixture
def umask():
    """Set the process umask for a test, restoring the old one afterwards."""
    old = os.umask(0o022)
    try:
        yield os.umask
    finally:
        os.umask(old)


def test_atomic_writes_honour_the_umask(tmp_path, umask):
    for mask, mode in ((0o022, 0o644), (0o077, 0o600), (0o002, 0o664)):
        umask(mask)
        paths = [write_json(tmp_path / f"a{mask}.json", {"v": 1}),
                 save_torch(tmp_path / f"c{mask}.pt", {"format": 1}),
                 atomic_write(tmp_path / f"b{mask}.bin", lambda fh: fh.write(b"x"))]
        with atomic_path(tmp_path / f"d{mask}.txt", suffix=".txt") as tmp:
            assert tmp.name.endswith(".txt") and tmp.parent == tmp_path
            tmp.write_text("by name")
        paths.append(tmp_path / f"d{mask}.txt")
        for p in paths:
            assert stat.S_IMODE(p.stat().st_mode) == mode, (p.name, oct(p.stat().st_mode), oct(mask))
    assert (tmp_path / "d18.txt").read_text() == "by name"
    assert not [p for p in tmp_path.iterdir() if is_temp_file(p)]


class _Marker:
    """Unpickling this creates a file: proof that a loader ran code from the checkpoint."""

    def __init__(self, path):
        self.path = str(path)

    def __reduce__(self):
        return (open, (self.path, "w"))


def test_checkpoint_with_pickled_code_is_refused_without_running_it(tmp_path):
    marker = tmp_path / "code-ran"
    save_torch(tmp_path / "evil.pt", {"format": 1, "config": {}, "agent": {"hook": _Marker(marker)}})
    with pytest.raises(CheckpointError, match="refusing to load") as info:
        load_checkpoint(tmp_path / "evil.pt")
    assert "io.open" in str(info.value) and "\n" not in str(info.value)
    assert not marker.exists()
    save_torch(tmp_path / "fn.pt", {"format": 1, "fn": print})
    with pytest.raises(CheckpointError, match="refusing to load.*builtins.print"):
        load_checkpoint(tmp_path / "fn.pt")


def test_numpy_state_loads_weights_only(tmp_path):
    rng = np.random.default_rng(7)
    rng.random(3)
    state = {"format": 1, "rng": rng.bit_generator.state, "legacy": np.random.RandomState(3).get_state(),
             "arrays": [np.arange(4).astype(dt) for dt in ("float32", "int64", "uint8", "bool")],
             "scalar": np.float64(2.5), "nested": {"t": torch.ones(2), "x": (1, "a", None, 2.0)}}
    save_torch(tmp_path / "np.pt", state)
    assert checkpoint_globals(tmp_path / "np.pt") == []
    back = load_checkpoint(tmp_path / "np.pt")
    again = np.random.default_rng(0)
    again.bit_generator.state = back["rng"]
    assert again.random() == rng.random()
    assert back["legacy"][0] == "MT19937" and np.array_equal(back["legacy"][1], state["legacy"][1])
    for a, b in zip(back["arrays"], state["arrays"]):
        assert a.dtype == b.dtype and np.array_equal(a, b)
    assert back["scalar"] == 2.5 and back["nested"]["x"] == (1, "a", None, 2.0)
    assert load_checkpoint(tmp_path / "np.pt", mmap=True)["nested"]["t"].tolist() == [1.0, 1.0]


def test_truncate_csv_keeps_rows_before_the_cut_and_drops_a_torn_row(tmp_path):
    path = tmp_path / "m.csv"
    path.write_bytes(b"episode,return\r\n0,0.5\r\n1,0.25\r\n2,0.75\r\n3,1")    # a kill mid-row
    truncate_csv(path, "episode", 2)
    assert path.read_bytes() == b"episode,return\r\n0,0.5\r\n1,0.25\r\n"
    truncate_csv(path, "episode", 5)                                          # nothing to cut
    assert path.read_bytes() == b"episode,return\r\n0,0.5\r\n1,0.25\r\n"
    path.write_bytes(b"epi")                                                  # header cut short
    truncate_csv(path, "episode", 2)
    assert not path.exists()
    truncate_csv(tmp_path / "missing.csv", "episode", 2)
    assert not (tmp_path / "missing.csv").exists()


def test_a_folder_that_refuses_the_temporary_file_is_reported_by_the_files_own_name(tmp_path, monkeypatch):
    import hubsgo_ppl.experiments.io as io_mod

    def refuse(path, suffix=""):
        raise PermissionError(1, "Operation not permitted", str(path.parent / ".eval.json.1234.tmp"))

    monkeypatch.setattr(io_mod, "_create_temp", refuse)
    with pytest.raises(OSError) as err:
        io_mod.write_json(tmp_path / "eval.json", {"a": 1})
    assert err.value.filename == str(tmp_path / "eval.json") and err.value.strerror == "Operation not permitted"


def test_the_package_has_one_atomic_writer(tmp_path):
    from hubsgo_ppl.diagnostics import arviz, plots
    from hubsgo_ppl.experiments import io

    assert arviz.atomic_write is io.atomic_write and plots.atomic_write is io.atomic_write
    path = io.atomic_write(tmp_path / "a.png", lambda fh: fh.write(b"x"), suffix=".png")
    assert path.read_bytes() == b"x" and [p.name for p in tmp_path.iterdir()] == ["a.png"]
