from hubsgo_ppl.experiments.logger import CSVOutput, Logger, read_csv_rows


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
