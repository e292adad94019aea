"""A tiny study protocol for the web tests: a 10-trial threshold block, then 2 point answers in dB SL.

The answers ``FELT`` walk its staircase (start -6 dB, 4 dB then 2 dB steps) through six
reversals, for a threshold of -9 dB re the paper's levels; the point block then plays at
-9 + 6 = -3 dB. Its third block, at 24 dB SL (+15 dB re the paper's levels: funneling at
location 5 needs 2.5 V x 10^(15/20) = 14 V, over the 10 V limit), is refused when it is
planned on a calibration.
"""

TINY_PROTOCOL = """\
format = 1
name = "tiny-threshold"
description = "a threshold block, then point answers in dB SL"

[[blocks]]
name = "threshold"
response = "detection"
methods = ["funneling"]
locations = [5]
levels = [-6.0]
repetitions = 10

[[blocks]]
name = "where"
response = "point"
methods = ["funneling"]
locations = [1, 9]
levels = [6.0]
level_unit = "dB SL"
repetitions = 1

[[blocks]]
name = "too-loud"
response = "point"
methods = ["funneling"]
locations = [5]
levels = [24.0]
level_unit = "dB SL"
repetitions = 1
"""

#: Answers to the threshold block, in order (1 felt): six reversals.
FELT = (1, 0, 1, 1, 0, 1, 1, 0, 1, 1)
#: The threshold they give, dB re the level rule (the mean of the reversals after the first two).
THRESHOLD_DB = -9.0
