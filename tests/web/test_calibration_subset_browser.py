"""In a real chromium: the calibration card offers the subset plans, and a calibration of
five points says which points were predicted."""

from __future__ import annotations

import pytest

from .conftest import login

pytestmark = [pytest.mark.browser, pytest.mark.slow]


def test_the_card_offers_the_subset_plan_and_names_the_predicted_points(server, page):
    assert server.api("POST", "/api/participants", json={"participant_id": "P44"}).status_code == 201
    login(page, server)
    page.wait_for_function("document.getElementById('cal-points').options.length === 4")
    assert page.eval_on_selector_all("#cal-points option", "os => os.map((o) => o.textContent)") == [
        "all 13 points", "9 points, predict 4", "7 points, predict 6", "5 points, predict 8"]
    assert "measures" not in page.inner_text("#cal-plan")  # every point: nothing predicted
    page.select_option("#cal-points", "5")
    assert "measures 5 of 13 points and predicts the other 8" in page.inner_text("#cal-plan")
    page.select_option("#participant", "P44")
    page.click("#calibrate")
    page.wait_for_function("document.getElementById('calibrate').disabled")
    page.wait_for_function("!document.getElementById('calibrate').disabled", timeout=240_000)
    assert "saved" in page.inner_text("#cal-message"), page.inner_text("#calibration-card")
    page.wait_for_selector("#cal-predicted")
    text = page.inner_text("#cal-predicted")
    assert "Measured 5 of 13 points" in text and "1, 2, 3, 4, 6, 7, 8, 9" in text, text
