"""write_json: the record's layout, and a rebuild on another machine that changes no number
leaves the file as it was."""

from __future__ import annotations

import json

from s3rl_torchrl.report import records


def test_a_record_is_rewritten_only_when_its_numbers_change(tmp_path, monkeypatch):
    path = tmp_path / "out" / "record.json"
    monkeypatch.setattr(records.platform, "platform", lambda: "machine-a")
    records.write_json(path, {"runs": [(1, 2.5)], "by_seed": {10: 0.5}}, "cmd")
    first = path.read_text()
    assert json.loads(first) == {"command": "cmd", "runs": [[1, 2.5]], "by_seed": {"10": 0.5},
                                 "machine": json.loads(first)["machine"]}
    assert json.loads(first)["machine"]["platform"] == "machine-a"

    monkeypatch.setattr(records.platform, "platform", lambda: "machine-b")
    records.write_json(path, {"runs": [(1, 2.5)], "by_seed": {10: 0.5}}, "cmd")
    assert path.read_text() == first  # same command and numbers: the first machine's record

    records.write_json(path, {"runs": [(1, 2.6)], "by_seed": {10: 0.5}}, "cmd")
    assert json.loads(path.read_text())["runs"] == [[1, 2.6]]
    assert json.loads(path.read_text())["machine"]["platform"] == "machine-b"

    path.write_text("not json")
    records.write_json(path, {"runs": []}, "cmd")
    assert json.loads(path.read_text())["runs"] == []
