"""A two-corner protocol for the studies' tests: funneling and the inverse filter at locations
1 and 9, -6 dB re the paper's levels, one repetition, one training trial, seed 7."""


def corner_protocol(name: str, response: str) -> str:
    """The protocol's TOML text with a name and a response type ("location", "point", ...)."""
    return f"""\
format = 1
name = "{name}"

[[blocks]]
response = "{response}"
methods = ["funneling", "inverse"]
locations = [1, 9]
levels = [-6.0]
repetitions = 1
training_trials = 1
seed = 7
"""
