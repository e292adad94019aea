"""STUB of psychopy.constants: PsychoPy's status values (not PsychoPy)."""

NOT_STARTED = 0
PLAYING = STARTED = 1
PAUSED = 2
STOPPED = FINISHED = -1
STOPPING = 3
PRESSED, RELEASED = 1, -1
FOREVER = 1000000000


class priority:
    CRITICAL, HIGH, MEDIUM, LOW, EXCLUDE = 30, 20, 10, 0, -10
