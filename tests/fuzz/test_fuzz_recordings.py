"""Malformed and adversarial recordings for `spacearm diagnose`: a table or one clear line
(exit code 2 for bad input), never a traceback, with and without a column map."""
from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from typer.testing import CliRunner

from spacearm.console.main import app
from spacearm.offline.diagnosis.column_spec import ColumnSpecError, parse_columns
from spacearm.offline.diagnosis.csv_reader import read_any_csv
from spacearm.offline.diagnosis.recording_io import RecordingFormatError
from tests.fuzz.conftest import CaseCounter
from tests.fuzz.test_fuzz_files import mutate


def valid_csv(n: int = 7, rows: int = 60, header: bool = True) -> bytes:
    t = 0.02 * np.arange(rows)
    q = 0.1 * np.sin(t[:, None] + np.arange(n))
    data = np.column_stack([t, q, q, np.gradient(q, axis=0) / 0.02, 2.0 * q])
    names = ["t"] + [f"{p}_{i}" for p in ("q_cmd", "q", "dq", "tau") for i in range(1, n + 1)]
    lines = ([",".join(names)] if header else []) + [",".join(f"{x:.6g}" for x in row) for row in data]
    return ("\n".join(lines) + "\n").encode()


def check_table(table) -> None:
    assert len(table.t) >= 10 and np.all(np.diff(table.t) > 0)
    for x in (table.q, table.q_cmd, table.dq, table.tau, table.wrench):
        assert np.all(np.isfinite(x))


def read_or_refuse(path: Path, columns: str | None = None, command: str = "recorded") -> None:
    try:
        table, _ = read_any_csv(path, parse_columns(columns), command)
    except ColumnSpecError:
        return
    except RecordingFormatError as exc:
        assert "\n" not in str(exc).strip() and (str(path) in str(exc) or "--" in str(exc))
        return
    check_table(table)


@given(data=st.data())
def test_mutated_csv_recording_reads_or_names_the_problem(data):
    CaseCounter.hit("files_diagnosis_csv")
    header = data.draw(st.booleans())
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "rec.csv"
        path.write_bytes(mutate(valid_csv(header=header), data))
        columns = None if header else "t=#1,q_cmd_1..7=#2..8,q_1..7=#9..15"
        read_or_refuse(path, columns, data.draw(st.sampled_from(["recorded", "measured"])))


@given(text=st.text(alphabet="tq_cmdau#0123456789.=,*/+-degx ", max_size=60))
def test_any_column_expression_parses_or_names_the_problem(text):
    CaseCounter.hit("files_diagnosis_columns")
    try:
        specs = parse_columns(text)
    except ColumnSpecError as exc:
        assert "\n" not in str(exc)
        return
    for s in specs:
        assert math.isfinite(s.scale) and math.isfinite(s.offset)


ADVERSARIAL = {
    "empty": b"",
    "header_only": b"t,q_cmd_1,q_1\n",
    "binary": bytes(range(256)) * 4,
    "utf16": "t,q_cmd_1,q_1\n0,0,0\n".encode("utf-16"),
    "nan_everywhere": b"t,q_cmd_1,q_1\n" + b"nan,nan,nan\n" * 40,
    "inf_positions": b"t,q_cmd_1,q_1\n" + b"".join(f"{k},inf,-inf\n".encode() for k in range(40)),
    "huge_values": b"t,q_cmd_1,q_1\n" + b"".join(f"{k},1e308,1e308\n".encode() for k in range(40)),
    "time_backwards": b"t,q_cmd_1,q_1\n" + b"".join(f"{40 - k},0,0\n".encode() for k in range(40)),
    "time_constant": b"t,q_cmd_1,q_1\n" + b"".join(f"1,{k},{k}\n".encode() for k in range(40)),
    "time_far_jump": b"t,q_cmd_1,q_1\n" + b"".join(f"{k if k < 39 else 1e12},0,0\n".encode() for k in range(40)),
    "one_column": b"".join(f"{k}\n".encode() for k in range(40)),
    "ragged": b"t,q_cmd_1,q_1,tau_1\n" + b"".join((f"{k},0.{k}" + (",0.1,1" if k % 3 else "") + "\n").encode()
                                                  for k in range(40)),
    "semicolons": b"t;q_cmd_1;q_1\n" + b"".join(f"{0.02 * k};0;0\n".encode() for k in range(40)),
    "degrees_unscaled": b"t,q_cmd_1,q_1\n" + b"".join(f"{k},{9000 + k},{9000 + k}\n".encode() for k in range(40)),
    "joint_100": ("t," + ",".join(f"q_cmd_{i},q_{i}" for i in range(1, 101)) + "\n").encode()
                 + b"".join((f"{k}," + ",".join(["0"] * 200) + "\n").encode() for k in range(12)),
    "quoted": b'"t","q_cmd_1","q_1"\n' + b"".join(f'"{k}","0","0"\n'.encode() for k in range(40)),
    "comments_and_blank": b"# logger v1\n\nt,q_cmd_1,q_1\n" + b"".join(f"{k},0,0\n\n".encode() for k in range(40)),
    "nine_rows": b"t,q_cmd_1,q_1\n" + b"".join(f"{k},0,0\n".encode() for k in range(9)),
    # hypothesis's draw (delete 5 bytes at 459, truncate at 2772): ten 7-joint rows with a broken
    # row, fewer than the gear fit's 25-row envelope window, which came back 25 long (IndexError)
    "seven_joints_ten_rows": (lambda b: bytes(b[:459] + b[464:2777]))(valid_csv(rows=80)),
}


@pytest.mark.parametrize("name", sorted(ADVERSARIAL))
def test_adversarial_recording_gets_one_line_or_a_diagnosis(name, tmp_path):
    path = tmp_path / f"{name}.csv"
    path.write_bytes(ADVERSARIAL[name])
    for args in (["--dry-run"], ["--report", str(tmp_path / "d"), "--json"]):
        res = CliRunner().invoke(app, ["diagnose", str(path), *args])
        assert res.exit_code in (0, 1, 2), res.output
        assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
        if res.exit_code:
            # one coded line (a JSON object under --json): the console's error contract
            assert res.output.strip().count("\n") == 0 and res.output.startswith(("error[bad_recording]: ", '{"ok": false'))


@settings(max_examples=12)
@given(data=st.data())
def test_mutated_seven_joint_recording_diagnoses_without_a_traceback(data, tmp_path_factory):
    """The whole pipeline (reader, replay, fits, report) on damaged 7-joint recordings."""
    CaseCounter.hit("files_diagnosis_full")
    d = tmp_path_factory.mktemp("full")
    path = d / "rec.csv"
    path.write_bytes(mutate(valid_csv(rows=80), data))
    res = CliRunner().invoke(app, ["diagnose", str(path), "--report", str(d / "out")])
    assert res.exit_code in (0, 1, 2), res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
