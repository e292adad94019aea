"""Turn a rig name (``--rig simulated|audio|nidaq``) into a rig object."""

from __future__ import annotations

from pathlib import Path

from .._validation import check_choice
from ..errors import ValidationError
from ..layout import ArrayLayout
from .base import Rig

__all__ = ["RIG_KINDS", "load_layout", "make_rig"]

RIG_KINDS = ("simulated", "audio", "nidaq")


def make_rig(
    kind: str = "simulated", *, config: object | None = None, seed: int | None = None,
    layout: ArrayLayout | str | Path | None = None, skin: str | None = None,
) -> Rig:
    """Build a rig by name.

    Parameters
    ----------
    kind : {"simulated", "audio", "nidaq"}
        Which backend.
    config : str, Path, dict or RigConfig, optional
        Hardware settings (device, channels, amplifier gain, vibrometer, limits): a
        ``.toml``/``.json`` file (see ``examples/rigs/``), a mapping of the same content,
        or a loaded :class:`~vibrofocus.rigs.config.RigConfig`. Required by ``audio`` and
        ``nidaq``, whose ``kind`` it must match; ignored by the simulated rig.
    seed : int, optional
        Participant seed of the simulated forearm (default 0).
    layout : ArrayLayout or path-like, optional
        The array, or a layout file (``vibrofocus design-layout``'s layout.json,
        docs/file-formats.md, "Layout files"); default the reference setup.
    skin : str, optional
        Skin preset of the simulated forearm (``nominal``, ``low``, ``high``,
        ``voigt-fit``; default ``nominal``). Hardware rigs refuse it.
    """
    check_choice(kind, "rig", RIG_KINDS)
    if isinstance(layout, (str, Path)):
        layout = load_layout(layout)
    if kind == "simulated":
        from .simulated import SimulatedForearm  # imported here: the arm's model is not needed for hardware

        return SimulatedForearm(seed=0 if seed is None else seed, layout=layout, skin=skin)
    if skin is not None:
        raise ValidationError(f"--skin describes the simulated forearm; the {kind} rig measures a real arm")
    from .config import RigConfig, load_rig_config, parse_rig_config

    if config is None:
        raise ValidationError(
            f"the {kind} rig needs a rig config file (device, channels, amplifier gain, vibrometer); "
            f"see examples/rigs/{kind}.toml"
        )
    if isinstance(config, (str, Path)):
        cfg = load_rig_config(config)
    elif isinstance(config, (dict, RigConfig)):
        cfg = parse_rig_config(config)
    else:
        raise ValidationError(f"config must be a path, a mapping or a RigConfig, got {type(config).__name__}")
    if cfg.kind != kind:
        raise ValidationError(f"the rig config is for a {cfg.kind!r} rig, but --rig asks for {kind!r}")
    if kind == "audio":
        from .audio import AudioRig

        return AudioRig(cfg, layout=layout)
    from .nidaq import NidaqRig

    return NidaqRig(cfg, layout=layout)


def load_layout(path: str | Path) -> ArrayLayout:
    """An array layout from a layout file (docs/file-formats.md, "Layout files").

    Parameters
    ----------
    path : path-like
        A ``layout.json`` (``vibrofocus design-layout``), or a JSON object of
        :meth:`ArrayLayout.to_dict`.

    Returns
    -------
    ArrayLayout
    """
    from .._atomic import protect
    from ..io import read_layout_json

    protect(path, "layout")
    try:
        return ArrayLayout.from_dict(read_layout_json(path))
    except (TypeError, ValueError) as exc:  # not numbers, ragged lists
        raise ValidationError(f"{path} does not describe an array layout: {exc}") from None
