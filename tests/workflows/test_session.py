"""Planning a session renders every stimulus first; the store then holds the session once."""

from __future__ import annotations

import pytest

from vibrofocus.errors import StudyError
from vibrofocus.studies import StudyStore
from vibrofocus.workflows import plan_session


class _Renderer:
    """Records what it is asked to render; refuses when told to (a design that does not fit)."""

    def __init__(self, refuse: bool = False):
        self.refuse, self.asked = refuse, []

    def prepare(self, methods, locations, **kwargs):
        self.asked.append((tuple(methods), tuple(locations), sorted(kwargs)))
        if self.refuse:
            raise StudyError("a stimulus does not fit this calibration")


def test_a_session_is_stored_only_after_every_stimulus_is_rendered(tmp_path):
    with StudyStore(tmp_path / "s.sqlite") as store:
        store.add_participant("P01")
        refusing = _Renderer(refuse=True)
        with pytest.raises(StudyError, match="does not fit"):
            plan_session(store, "P01", 1, seed=3, renderer=refusing, rig=object())
        assert store.sessions("P01") == []
        assert refusing.asked == [(("funneling", "inverse", "combination"), tuple(range(1, 10)), ["rig"])]
        sid, created = plan_session(store, "P01", 1, seed=3, renderer=_Renderer(), reuse="open")
        assert created and store.session(sid).n_trials == 5 + 3 * 9 * 3
        # The same participant and study again: the open session, not a second one.
        assert plan_session(store, "P01", 1, seed=4, reuse="open") == (sid, False)
        # Without reuse (the web app plans sessions side by side): a new one each time.
        assert plan_session(store, "P01", 1, seed=4)[0] != sid
