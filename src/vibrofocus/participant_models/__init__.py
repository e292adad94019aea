"""Models of participants: perceptual models that answer a study in place of a person (not data).

The new name of :mod:`vibrofocus.simulation`, whose files it re-exports for now (they move
here in a later release; DEVELOPING.md, "Names"). Every submodule is reachable under this
name: ``from vibrofocus.participant_models.perception import PerceptualModel``. The model,
its stages and their sources: docs/simulated-participants.md.
"""

from .._deprecated import alias_submodules
from ..simulation import *  # noqa: F403 - the re-export is the point
from ..simulation import __all__  # noqa: F401

alias_submodules(__name__, "vibrofocus.simulation")
