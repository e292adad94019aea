"""The free parameters of a hypothesis: names, bounds and where the bounds come from.

A hypothesis of the simulated participants fixes most of
:class:`~vibrofocus.simulation.perception.PerceptualModel`'s parameters and leaves a few
free, each within a range that has a source (or is stated as an assumption). Fitting
(to the paper's statistics, or to a lab's trials by likelihood) moves only those.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from .._validation import check_in_range
from ..errors import ValidationError
from .perception import PerceptualModel

__all__ = ["ParameterRange", "apply_parameters", "read_parameters", "ordered_pairs", "model_at"]


@dataclass(frozen=True)
class ParameterRange:
    """One free parameter of a hypothesis.

    Attributes
    ----------
    name : str
        A field of :class:`~vibrofocus.simulation.perception.PerceptualModel`.
    lo, hi : float
        The range the parameter may take, in the field's units (SI: m, dB, ...).
    source : str
        Where the range comes from (title, venue, year, figure or table), or
        ``"assumption: ..."`` with why that range.
    index : int or None
        For a field that is a pair (a population range such as ``acuity_sd_m``), which
        element; None for a scalar field.
    """

    name: str
    lo: float
    hi: float
    source: str
    index: int | None = None

    def __post_init__(self) -> None:
        fields = PerceptualModel().to_dict()
        if self.name not in fields:
            raise ValidationError(f"unknown perceptual model parameter {self.name!r}")
        is_pair = isinstance(fields[self.name], (tuple, list))
        if is_pair != (self.index is not None):
            raise ValidationError(f"parameter {self.name!r} needs index "
                                  f"{'0 or 1' if is_pair else 'None'}, got {self.index!r}")
        lo = check_in_range(self.lo, f"{self.key} lo", -math.inf, math.inf, inclusive=False)
        hi = check_in_range(self.hi, f"{self.key} hi", -math.inf, math.inf, inclusive=False)
        if not lo < hi:
            raise ValidationError(f"{self.key}: lo must be below hi, got ({lo}, {hi})")
        if not isinstance(self.source, str) or not self.source.strip():
            raise ValidationError(f"{self.key}: a free parameter needs a source or a stated assumption")

    @property
    def key(self) -> str:
        """The parameter's name, with ``[index]`` for an element of a pair."""
        return self.name if self.index is None else f"{self.name}[{self.index}]"


def read_parameters(model: PerceptualModel, ranges: Sequence[ParameterRange]) -> list[float]:
    """The values of ``ranges``' parameters in ``model``, in order."""
    d = model.to_dict()
    return [float(d[r.name] if r.index is None else d[r.name][r.index]) for r in ranges]


def apply_parameters(model: PerceptualModel, ranges: Sequence[ParameterRange],
                     values: Sequence[float] | Mapping[str, float]) -> PerceptualModel:
    """``model`` with ``ranges``' parameters set to ``values`` (in order, or by key).

    Raises
    ------
    ValidationError
        A value outside its range, or a missing key.
    """
    if isinstance(values, Mapping):
        missing = [r.key for r in ranges if r.key not in values]
        if missing:
            raise ValidationError(f"no value for {', '.join(missing)}")
        values = [values[r.key] for r in ranges]
    if len(values) != len(ranges):
        raise ValidationError(f"{len(ranges)} parameters, got {len(values)} values")
    d: dict[str, Any] = model.to_dict()
    for r, v in zip(ranges, values):
        v = check_in_range(v, r.key, r.lo, r.hi)
        if r.index is None:
            d[r.name] = v
        else:
            pair = list(d[r.name])
            pair[r.index] = v
            d[r.name] = tuple(pair)
    return model.replace(**d)


def ordered_pairs(ranges: Sequence[ParameterRange], values: Sequence[float]) -> list[float]:
    """``values`` with the two ends of each population range (both free) in order, low first.

    A population range (lo, hi) is drawn from uniformly, which needs lo <= hi; a search or
    an optimizer that moves both ends may cross them. Both ends of a pair share one range
    (the same ``lo`` and ``hi``), so sorting keeps each inside it.
    """
    out = [float(v) for v in values]
    for name in {r.name for r in ranges if r.index is not None}:
        pair = [k for k, r in enumerate(ranges) if r.name == name]
        if len(pair) == 2:
            a, b = sorted(out[k] for k in pair)
            out[pair[0]], out[pair[1]] = (a, b) if ranges[pair[0]].index == 0 else (b, a)
    return out


def model_at(h: Any, values: Sequence[float] | Mapping[str, float] | None) -> PerceptualModel:
    """The hypothesis' model with its free parameters at ``values``.

    Parameters
    ----------
    h : Hypothesis
    values : sequence or mapping of float, or None
        In the order of ``h.free_parameters`` or by key; None: as the hypothesis has them.

    Returns
    -------
    PerceptualModel
    """
    m = h.model()
    if values is None or not h.free_parameters:
        return m
    if isinstance(values, Mapping):
        if any(r.key not in values for r in h.free_parameters):
            return apply_parameters(m, h.free_parameters, values)  # names what is missing
        values = [values[r.key] for r in h.free_parameters]
    # The optimizer moves the two ends of a population range apart: kept in order.
    return apply_parameters(m, h.free_parameters, ordered_pairs(h.free_parameters, values))
