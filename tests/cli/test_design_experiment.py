"""``vibrofocus design-experiment``: a designed protocol that simulate-study accepts, and a report."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from vibrofocus.cli.main import app
from vibrofocus.studies.protocol_files import load_protocol

runner = CliRunner()
SMALL = ["--forearms", "1", "--traits", "2", "--parameter-draws", "1", "--budget", "12", "--levels", "0,-20",
         "--methods", "funneling,inverse"]


def test_design_experiment_writes_a_protocol_and_its_report(tmp_path):
    out = tmp_path / "design"
    res = runner.invoke(app, ["design-experiment", *SMALL, "--participants", "1,2", "--studies", "4", "--pool", "4",
                              "--score-forearms", "2", "--score-draws", "2", "--no-dask",
                              "--out", str(out)])
    assert res.exit_code == 0, res.output
    proto = load_protocol(out / "protocol.toml")
    proto.check_runnable()
    report = json.loads((out / "design.json").read_text())
    assert sum(b["trials"] for b in report["blocks"]) == report["trials"] <= 12
    assert set(report["identification"]["rates"]) == {"designed", "paper"}
    assert (out / "identification.png").stat().st_size > 0 and (out / "design-map.png").stat().st_size > 0
    md = (out / "design.md").read_text()
    assert "not data" in md
    # The rates assume known parameters; the report and the terminal say the free fit's are lower.
    assert "with the free fit of `analyze --hypotheses`" in md
    assert "with the free fit of `analyze" in " ".join(res.output.split())


def test_design_experiment_refuses_bad_input_in_one_line():
    for args, words in ((["--levels", "loud"], "--levels must be numbers"),
                        (["--levels", "6"], "drive limit"),
                        (["--hypotheses", "telepathy"], "telepathy"),
                        (["--parameter-spread", "2"], "--parameter-spread")):
        res = runner.invoke(app, ["design-experiment", *SMALL[:-4], *args, "--studies", "0"])
        assert res.exit_code != 0
        assert words in res.output and "Traceback" not in res.output, res.output


def test_rival_fits_from_a_recovery_file_join_the_design_and_a_bad_file_is_one_line(tmp_path):
    from vibrofocus.simulation.hypotheses import hypothesis

    mid = {r.key: 0.5 * (r.lo + r.hi) for r in hypothesis("level-reliability").free_parameters}
    good = tmp_path / "fits.jsonl"
    good.write_text(json.dumps({"settings": {}}) + "\n"
                    + json.dumps({"true": "v3-centroid", "params": {"level-reliability": mid}}) + "\n")
    out = tmp_path / "design"
    res = runner.invoke(app, ["design-experiment", *SMALL, "--hypotheses", "v3-centroid,level-reliability",
                              "--rival-fits", str(good), "--studies", "0", "--out", str(out)])
    assert res.exit_code == 0, res.output
    draws = json.loads((out / "design.json").read_text())["parameter_draws"]
    assert draws["level-reliability"]["rival_fits"] == [mid] and "rival_fits" not in draws["v3-centroid"]
    bad = tmp_path / "bad.jsonl"
    for text, words in (('{"settings": {}}\n{"true": "v3-centroid", "params": {"level-reliability": 3}}\n',
                         "line 2 of the rival fits file"),
                        ('{"settings": {}}\nnot json\n', "line 2 of the rival fits file"),
                        (json.dumps({"true": "v3-centroid", "params": {"level-reliability": {**mid, "nope": 1.0}}}),
                         "rival_fits: a parameter set of level-reliability: 'nope' not among its free parameters")):
        bad.write_text(text)
        res = runner.invoke(app, ["design-experiment", *SMALL, "--hypotheses", "v3-centroid,level-reliability",
                                  "--rival-fits", str(bad), "--studies", "0", "--out", str(tmp_path / "no")])
        assert res.exit_code != 0 and words in res.output and "Traceback" not in res.output, res.output
        assert not (tmp_path / "no").exists()
