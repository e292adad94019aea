"""Ids are checked whole: a trailing newline (which ``$`` lets through ``re.match``) is refused everywhere."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient
from typer.testing import CliRunner

from vibrofocus.cli.main import app
from vibrofocus.errors import StudyError
from vibrofocus.studies import StudyStore
from vibrofocus.studies.storage import check_participant_id

BAD = ["P01\n", "P01\r\n", "P01\t", "\nP01"]
runner = CliRunner()


@pytest.mark.parametrize("pid", BAD)
def test_the_python_api_refuses_an_id_with_a_newline(tmp_path, pid):
    with pytest.raises(StudyError, match="participant id must be"):
        check_participant_id(pid)
    with StudyStore(tmp_path / "s.sqlite") as store:
        with pytest.raises(StudyError, match="participant id must be"):
            store.add_participant(pid)
        assert store.participants() == []
        store.add_participant("P01")
        sid = store.create_session("P01", 1, seed=1, config={"repetitions": 1, "n_training": 0,
                                                             "methods": ["inverse"], "locations": [4]})
        with pytest.raises(StudyError, match="event kind"):
            store.log_event(sid, "cue\n")
        with pytest.raises(StudyError):
            store.record_answer(sid, 0, 4, 0.5, answer_id="abcdefgh\n")
        assert store.answers(sid) == []


def test_the_cli_refuses_an_id_with_a_newline(tmp_path):
    result = runner.invoke(app, ["calibrate", "-p", "P01\n", "--out", str(tmp_path / "c.nc")])
    assert result.exit_code == 2 and "participant id must be" in result.output, result.output
    assert list(tmp_path.iterdir()) == []


def test_the_web_api_refuses_an_id_with_a_newline(tmp_path):
    from vibrofocus.web.app import create_app

    token = "n" * 32
    web = create_app(tmp_path / "s.sqlite", token=token, allowed_hosts=("testserver",), resume=False)
    with TestClient(web, headers={"X-Vibrofocus-Token": token, "Origin": "http://testserver"}) as client:
        assert client.post("/api/participants", json={"participant_id": "P01\n"}).status_code == 422
        assert client.get("/api/participants").json() == []
