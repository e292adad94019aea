"""The 1-up-2-down staircase of threshold blocks: PsychoPy's rule, replayed from the answers."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from vibrofocus.errors import StudyError
from vibrofocus.studies.staircase import Staircase

def _observer_answers(stair: Staircase, n: int, threshold_db: float, *, seed: int | None = None) -> list[int]:
    rng = None if seed is None else np.random.default_rng(seed)
    felt: list[int] = []
    for _ in range(n):
        level = stair.level_of(felt)
        p = float(level >= threshold_db) if rng is None else 1.0 / (1.0 + np.exp(-(level - threshold_db) / 1.5))
        felt.append(int(p >= 0.5) if rng is None else int(rng.random() < p))
    return felt


def test_the_staircase_walks_down_then_brackets_the_threshold():
    stair = Staircase(start_db=-4.0)
    felt = _observer_answers(stair, 40, -20.0)
    run = stair.run(felt)
    # The initial rule: one step of 4 dB down per felt tap until the first miss.
    assert run.levels_db[:6] == (-4.0, -8.0, -12.0, -16.0, -20.0, -24.0)
    assert felt[:6] == [1, 1, 1, 1, 1, 0]
    assert len(run.levels_db) == len(felt) + 1
    # A deterministic observer felt at -20 and not at -22: the reversals sit there, 2 dB apart.
    assert set(run.reversals_db[2:]) <= {-20.0, -22.0}
    assert run.threshold_db is not None and -22.0 <= run.threshold_db <= -20.0


def test_too_few_reversals_give_no_threshold_and_levels_stay_within_bounds():
    stair = Staircase(start_db=-10.0, max_db=-6.0, min_db=-30.0)
    run = stair.run([1] * 30)  # always felt: down to the floor, never a reversal
    assert run.threshold_db is None and run.reversals_db == ()
    assert min(run.levels_db) == -30.0
    run = stair.run([0] * 30)
    assert max(run.levels_db) == -6.0


def test_bad_staircases_and_answers_are_refused_in_one_line():
    with pytest.raises(StudyError, match="start_db 5 must lie within"):
        Staircase(start_db=5.0)
    with pytest.raises(StudyError, match="steps_db must be"):
        Staircase(start_db=-5.0, steps_db=(0.0,))
    with pytest.raises(StudyError, match="1 \\(felt\\) or 0"):
        Staircase(start_db=-5.0).run([2])
    with pytest.raises(StudyError, match="unknown staircase key"):
        Staircase.from_dict({"start_db": -5.0, "step": 2})
    assert Staircase.from_dict(Staircase(start_db=-5.0).to_dict()) == Staircase(start_db=-5.0)


PSYCHOPY_SCRIPT = """
import json, sys
from psychopy.data import StairHandler
answers = json.loads(sys.argv[1])
stair = StairHandler(startVal=-4.0, stepSizes=[4.0, 2.0], nUp=1, nDown=2, nTrials=len(answers), nReversals=2,
                     stepType="lin", minVal=-60.0, maxVal=0.0, applyInitialRule=True)
levels = []
for answer in answers:
    levels.append(next(stair))
    stair.addResponse(answer)
print("RESULT " + json.dumps({"levels": levels, "reversals": stair.reversalIntensities}))
"""


def test_the_levels_are_psychopys_stairhandler_levels(tmp_path):
    given = os.environ.get("VIBROFOCUS_TEST_PSYCHOPY")
    if not given or not (Path(given) / "psychopy").is_dir():
        pytest.skip("PsychoPy's wheel is not at hand (scripts/test.sh installs it, VIBROFOCUS_TEST_PSYCHOPY)")
    stair = Staircase(start_db=-4.0)
    # From above the threshold, and from below it (the first reversal is then a felt tap).
    for seed, threshold_db in ((1, -18.0), (2, -18.0), (4, -1.0)):
        felt = _observer_answers(stair, 50, threshold_db, seed=seed)
        env = dict(os.environ, PYTHONPATH=given, HOME=str(tmp_path), PYTHONDONTWRITEBYTECODE="1")
        proc = subprocess.run([sys.executable, "-c", PSYCHOPY_SCRIPT, json.dumps(felt)], cwd=tmp_path, env=env,
                              capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr[-2000:]
        reference = json.loads(proc.stdout.split("RESULT ", 1)[1])
        run = stair.run(felt)
        np.testing.assert_allclose(run.levels_db[:-1], reference["levels"], rtol=0, atol=1e-12)
        np.testing.assert_allclose(run.reversals_db, reference["reversals"], rtol=0, atol=1e-12)
