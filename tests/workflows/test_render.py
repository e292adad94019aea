"""The words of ``vibrofocus render``'s scaling to the drive limit."""

from vibrofocus.workflows.render import scaling_words


def test_scaling_words_say_the_direction_the_levels_and_why():
    assert scaling_words(10 / 9.33, 9.33, 10.0) == "scaled up ×1.07, from 9.33 V to the 10 V limit (equal peak)"
    assert scaling_words(10 / 11.8, 11.8, 10.0) == "scaled down ×0.847, from 11.8 V to the 10 V limit (over it)"
    assert scaling_words(1.0, 10.0, 10.0) == ""
