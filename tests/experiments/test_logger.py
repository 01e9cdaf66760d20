import os
import subprocess
import sys

import pytest
from stable_baselines3.common.logger import KVWriter
from stable_baselines3.common.logger import Logger as SB3Logger

from hubsgo_ppl.experiments import logger as logger_mod
from hubsgo_ppl.experiments.io import truncate_csv
from hubsgo_ppl.experiments.logger import CSVOutput, Logger, TensorBoardOutput, read_csv_rows


def test_csv_output_grows_header_and_keeps_rows(tmp_path):
    path = tmp_path / "m.csv"
    log = Logger([CSVOutput(path)])
    log.record("episode", 0)
    log.record("return", 0.5)
    log.dump(0)
    log.record("episode", 1)
    log.record("return", 0.7)
    log.record("critic/loss", 1.5)
    log.dump(1)
    rows = read_csv_rows(path)
    assert [r["episode"] for r in rows] == ["0", "1"]
    assert rows[0]["critic/loss"] == "" and rows[1]["critic/loss"] == "1.5"
    # reopening appends under the existing header
    log2 = Logger([CSVOutput(path)])
    log2.record("episode", 2)
    log2.record("return", 0.9)
    log2.record("critic/loss", 1.0)
    log2.dump(2)
    assert [r["return"] for r in read_csv_rows(path)] == ["0.5", "0.7", "0.9"]
    assert path.read_text().splitlines()[0] == "episode,return,critic/loss"


def test_keys_that_come_after_the_first_row_go_before_the_wall_time(tmp_path):
    """An agent whose losses start after its first episode logs the columns of one whose losses come at once."""
    path = tmp_path / "m.csv"
    out = CSVOutput(path)
    out.write({"episode": 0, "return": 0.0, "wall_time": 0.1}, 0)
    out.write({"episode": 1, "return": 1.0, "high/loss": 0.5, "wall_time": 0.2}, 1)
    assert path.read_text().splitlines()[0] == "episode,return,high/loss,wall_time"
    assert read_csv_rows(path)[0] == {"episode": "0", "return": "0.0", "high/loss": "", "wall_time": "0.1"}


def test_logger_is_sb3s_and_csv_honours_exclude(tmp_path):
    path = tmp_path / "m.csv"
    log = Logger([CSVOutput(path)])
    assert isinstance(log, SB3Logger) and log.outputs is log.output_formats
    log.record("episode", 0)
    log.record("debug/histogram_only", 3.0, exclude="csv")
    log.record("return", 0.25, exclude="tensorboard")
    log.dump(0)
    assert read_csv_rows(path) == [{"episode": "0", "return": "0.25"}]


def test_csv_columns_keep_first_seen_order_in_every_process(tmp_path):
    """SB3's CSV writer adds new columns in set order (hash-seed dependent); ours in first-seen order."""
    keys = [f"k{i}" for i in range(12)]
    script = ("import sys\nfrom hubsgo_ppl.experiments.logger import CSVOutput\n"
              "out = CSVOutput(sys.argv[1])\nout.write({'episode': 0}, 0)\n"
              f"out.write({{'episode': 1, **{{k: 1 for k in {keys!r}}}}}, 1)\n")
    headers = set()
    for seed in ("1", "2", "3"):
        path = tmp_path / f"m{seed}.csv"
        subprocess.run([sys.executable, "-c", script, str(path)], check=True,
                       env={**os.environ, "PYTHONHASHSEED": seed})
        headers.add(path.read_text().splitlines()[0])
    assert headers == {",".join(["episode", *keys])}


def test_new_column_rewrite_is_atomic(tmp_path, monkeypatch):
    """A failure while the header is rewritten leaves the earlier rows as they were."""
    path = tmp_path / "m.csv"
    out = CSVOutput(path)
    out.write({"episode": 0, "return": 0.5}, 0)
    before = path.read_bytes()

    def killed(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(logger_mod, "write_text", killed)
    with pytest.raises(KeyboardInterrupt):
        out.write({"episode": 1, "return": 0.7, "critic/loss": 2.0}, 1)
    assert path.read_bytes() == before


def test_resume_appends_after_the_truncated_rows(tmp_path):
    """What the harness does on --resume: cut the log back to the checkpoint, then reopen and append."""
    path = tmp_path / "m.csv"
    log = Logger([CSVOutput(path)])
    for ep in range(4):
        log.record("episode", ep)
        log.record("return", ep / 10)
        log.dump(ep)
    log.close()
    truncate_csv(path, "episode", 2)
    log = Logger([CSVOutput(path)])
    log.record("episode", 2)
    log.record("return", 0.9)
    log.dump(2)
    log.close()
    assert [(r["episode"], r["return"]) for r in read_csv_rows(path)] == [("0", "0.0"), ("1", "0.1"), ("2", "0.9")]


def test_logger_close_closes_every_output_even_if_one_fails():
    closed = []

    class Out(KVWriter):
        def __init__(self, name, fail=False):
            self.name, self.fail = name, fail

        def write(self, key_values, key_excluded, step=0):
            pass

        def close(self):
            closed.append(self.name)
            if self.fail:
                raise OSError("disk gone")

    log = Logger([Out("a", fail=True), Out("b")])
    with pytest.raises(OSError, match="disk gone"):
        log.close()
    assert closed == ["a", "b"]


def _scalars(folder, tag):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(folder))
    acc.Reload()
    return [(e.step, e.value) for e in acc.Scalars(tag)]


def test_tensorboard_resume_purges_events_after_the_checkpoint(tmp_path):
    first = Logger([TensorBoardOutput(tmp_path)])
    for step in (10, 20, 30):                       # 30: logged after the checkpoint at 20, then killed
        first.record("charts/return", float(step))
        first.dump(step)
    first.close()
    again = Logger([TensorBoardOutput(tmp_path, purge_step=21)])
    again.record("charts/return", 31.0)
    again.dump(30)
    again.close()
    assert [(s, v) for s, v in _scalars(tmp_path, "charts/return")] == [(10, 10.0), (20, 20.0), (30, 31.0)]
    assert len(list(tmp_path.glob("events.out.tfevents.*"))) == 2     # one per writer, none spare


def test_tensorboard_output_closes_its_writer(tmp_path):
    out = TensorBoardOutput(tmp_path)
    out.close()
    assert out.writer.all_writers is None


def test_a_log_that_is_a_symlink_is_refused_not_appended_through(tmp_path):
    from hubsgo_ppl.experiments.io import RunFileError
    from hubsgo_ppl.experiments.logger import CSVOutput

    target = tmp_path / "elsewhere.csv"
    target.write_text("episode,x\n0,1\n")
    link = tmp_path / "metrics.csv"
    link.symlink_to(target)
    out = CSVOutput(link)
    with pytest.raises(RunFileError, match="a symbolic link"):
        out.write({"episode": 1, "x": 2}, step=1)
    assert target.read_text() == "episode,x\n0,1\n"
