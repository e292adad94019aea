"""Planning of the studies: counts, seeded order, response rules."""

from collections import Counter

import pytest

from vibrofocus.errors import StudyError
from vibrofocus.studies import StudyDesign, format_response, parse_response, plan_trials


def test_study1_design_counts_each_condition_exactly_repetitions_times():
    design = StudyDesign(study=1)
    trials = plan_trials(design, seed=11)
    assert len(trials) == 86 == design.n_trials
    training = [t for t in trials if t.phase == "training"]
    main = [t for t in trials if t.phase == "main"]
    assert len(training) == 5 and len(main) == 81
    # Training first, then main; indices are the positions, numbers run within a phase.
    assert [t.trial_index for t in trials] == list(range(86))
    assert [t.trial for t in training] == [1, 2, 3, 4, 5]
    assert [t.trial for t in main] == list(range(1, 82))
    counts = Counter(t.condition() for t in main)
    assert set(counts) == {(m, loc) for m in ("funneling", "inverse", "combination") for loc in range(1, 10)}
    assert set(counts.values()) == {3}
    assert len(set(t.condition() for t in training)) == 5  # distinct training conditions


def test_same_seed_same_order_different_seed_different_order():
    design = StudyDesign(study=2)
    a = [t.condition() for t in plan_trials(design, seed=5)]
    b = [t.condition() for t in plan_trials(design, seed=5)]
    c = [t.condition() for t in plan_trials(design, seed=6)]
    assert a == b
    assert a != c
    assert Counter(a[5:]) == Counter(c[5:])  # same conditions, another order


def test_main_order_is_not_blocked_by_method():
    # A shuffled order mixes methods: the first 27 main trials are not all one method.
    main = [t for t in plan_trials(StudyDesign(), seed=1) if t.phase == "main"]
    assert len({t.method for t in main[:27]}) == 3


def test_custom_design_and_bad_designs():
    design = StudyDesign(study=1, methods=("inverse",), locations=(1, 2), repetitions=2, n_training=0)
    trials = plan_trials(design, seed=0)
    assert [t.phase for t in trials] == ["main"] * 4
    with pytest.raises(StudyError, match="unknown method 'shaker'"):
        StudyDesign(methods=("shaker",))
    with pytest.raises(StudyError, match="study must be 1 or 2"):
        StudyDesign(study=3)
    with pytest.raises(StudyError, match="repetitions"):
        StudyDesign(repetitions=0)
    with pytest.raises(StudyError, match="seed"):
        plan_trials(design, seed=-1)


@pytest.mark.parametrize("given, expected", [(5, (5,)), ("5", (5,)), (" 7 ", (7,)), ([3], (3,))])
def test_study1_accepts_exactly_one_location(given, expected):
    assert parse_response(given, StudyDesign(study=1)) == expected


@pytest.mark.parametrize("given, message", [
    (0, "outside the study's locations 1-9"),
    (10, "outside the study's locations 1-9"),
    ("", "empty"),
    ("x", "location numbers 1-9"),
    ("4 5", "exactly one location"),
    (True, "location numbers"),
    (2.5, "location numbers"),
])
def test_study1_refuses_bad_responses(given, message):
    with pytest.raises(StudyError, match=message):
        parse_response(given, StudyDesign(study=1))


def test_study2_accepts_several_distinct_locations_sorted():
    d2 = StudyDesign(study=2)
    assert parse_response("5 4", d2) == (4, 5)
    assert parse_response("45", d2) == (4, 5)  # keypad digits typed together
    assert parse_response([9, 1, 5], d2) == (1, 5, 9)
    assert format_response((5, 4)) == "4 5"
    with pytest.raises(StudyError, match="more than once"):
        parse_response("4 4", d2)
    with pytest.raises(StudyError, match="outside"):
        parse_response([4, 12], d2)
