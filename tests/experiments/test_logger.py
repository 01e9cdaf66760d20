import pytest

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


def test_logger_close_closes_every_output_even_if_one_fails():
    closed = []

    class Out:
        def __init__(self, name, fail=False):
            self.name, self.fail = name, fail

        def write(self, values, step):
            pass

        def close(self):
            closed.append(self.name)
            if self.fail:
                raise OSError("disk gone")

    log = Logger([Out("a", fail=True), Out("b")])
    with pytest.raises(OSError, match="disk gone"):
        log.close()
    assert closed == ["a", "b"]


def test_tensorboard_resume_purges_events_after_the_checkpoint(tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    first = TensorBoardOutput(tmp_path)
    for step in (10, 20, 30):                       # 30: logged after the checkpoint at 20, then killed
        first.write({"charts/return": float(step)}, step)
    first.close()
    again = TensorBoardOutput(tmp_path, purge_step=21)
    again.write({"charts/return": 31.0}, 30)
    again.close()
    acc = EventAccumulator(str(tmp_path))
    acc.Reload()
    assert [(e.step, e.value) for e in acc.Scalars("charts/return")] == [(10, 10.0), (20, 20.0), (30, 31.0)]
