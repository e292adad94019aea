"""Study protocols in the web app: the shipped ones, uploads, and sessions planned from a block.

The experimenter page plans a session from a protocol (docs/web.md, "Sessions from a
protocol"; the file format: docs/protocols.md): one of the shipped protocols
(``vibrofocus/studies/protocols/*.toml``) or one uploaded through ``POST /api/protocols``.
An upload is read by the same parser as ``study run --protocol``
(:func:`~vibrofocus.studies.protocol_files.parse_protocol`): a bad one gets its one line
naming the field and the line, and nothing is stored. A good one is kept in the server's
files folder (``protocols/<name>.toml``), so that its later blocks can be planned from it;
a second upload of another text under the same name is refused, since every session
names its protocol only by name.

A session of a block is planned as ``study run --protocol`` plans it: the block's design,
the protocol's name and block stored in the session's config, a block in dB SL on the
participant's threshold from the threshold block before it
(:meth:`~vibrofocus.studies.protocol_files.StudyProtocol.participant_threshold`), and a
level over the drive limit refused before anything is written
(:func:`~vibrofocus.studies.engine.check_drive_levels`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from fastapi import HTTPException

from ..errors import StudyError
from ..studies.protocol_files import (MAX_PROTOCOL_BYTES, SHIPPED_PROTOCOLS, StudyProtocol, parse_protocol,
                                      shipped_protocol)
from ..workflows.session import first_unfinished_block
from .private import private_dir

__all__ = ["find_protocol", "protocol_summary", "staircase_state", "protocols_folder",
           "read_uploaded"]


def protocols_folder(web: Any) -> Path:
    """The folder of the uploaded protocols (private to the server's user)."""
    folder = web.data_dir / "protocols"
    private_dir(folder, "protocols folder")
    return folder


def read_uploaded(path: Path, name: str) -> StudyProtocol:
    with open(path, "rb") as fh:
        raw = fh.read(MAX_PROTOCOL_BYTES + 1)
    return parse_protocol(raw.decode("utf-8"), f"{name}.toml")


def find_protocol(web: Any, name: str) -> StudyProtocol:
    """The protocol ``name``: a shipped one, else one uploaded to this server (404 if none)."""
    if name in SHIPPED_PROTOCOLS:
        return shipped_protocol(name)
    path = protocols_folder(web) / f"{name}.toml"
    if not path.is_file():
        raise HTTPException(404, detail=(f"No protocol {name!r} on this server: the shipped ones are "
                                         f"{', '.join(SHIPPED_PROTOCOLS)}; upload a protocol file first."))
    return read_uploaded(path, name)


def protocol_summary(protocol: StudyProtocol, *, shipped: bool) -> dict[str, Any]:
    """What the experimenter page lists of a protocol: its name, text and blocks."""
    return {
        "name": protocol.name, "description": protocol.description, "shipped": shipped,
        "blocks": [{"index": b.index, "name": b.name, "response": b.response, "study": b.study,
                    "methods": list(b.methods), "locations": None if b.locations is None else list(b.locations),
                    "levels": list(b.levels), "level_unit": b.level_unit,
                    "n_trials": b.training_trials + len(b.methods) * len(b.locations or b.points_mm or ()) * b.repetitions}
                   for b in protocol.blocks],
    }


def plan_block(web: Any, protocol: StudyProtocol, participant_id: str, block: int | None,
               calibration_id: int | None) -> tuple[int, int, dict[str, Any]]:
    """``(study, block, config)`` of a session of ``protocol``'s block (default: the first unfinished).

    Checked before anything is written: the block runnable, a threshold for a block in
    dB SL, and with a calibration every stimulus rendered and its level within the drive
    limit (:func:`~vibrofocus.studies.engine.check_drive_levels`).
    """
    from ..studies.engine import check_drive_levels
    from ..studies.protocol import StudyDesign

    protocol.check_runnable()
    with web.db:
        if block is None:
            block = first_unfinished_block(web.store, participant_id, protocol)
        if block >= len(protocol.blocks):
            raise StudyError(f"protocol {protocol.name!r} has {len(protocol.blocks)} block(s): no block {block}")
        threshold_db = protocol.participant_threshold(web.store, participant_id, block)
    b = protocol.blocks[block]
    assert b.study is not None  # check_runnable
    config = protocol.session_config(block, threshold_db)
    if calibration_id is not None:
        design = StudyDesign.from_config(b.study, config)
        bank = web.bank(calibration_id, levels=design.levels)
        bank.prepare(design.methods, design.locations)
        check_drive_levels(bank, design, where=protocol.level_where(block))
        if design.point:  # the picture the participant points on: this arm's layout
            config["layout"] = web.calibration(calibration_id).layout.to_dict()
    return b.study, block, config


def staircase_state(store: Any, info: Any) -> dict[str, Any] | None:
    """A threshold session's staircase as the experimenter page shows it; None for other sessions.

    ``level_db`` the next trial's level, ``reversals`` the reversals so far, and
    ``threshold_db`` the threshold the store keeps for it (None before the block's last
    answer, or where the staircase reversed too few times), all dB re the level rule.
    """
    staircase = info.design.staircase
    if staircase is None:
        return None
    felt = [a.response for a in store.answers(info.session_id) if a.trial_index >= info.design.n_training]
    run = staircase.run(felt)  # what the store's threshold is computed from, with the block's last answer
    return {"level_db": run.next_db, "reversals": len(run.reversals_db), "levels_db": list(run.levels_db),
            "threshold_db": run.threshold_db if info.finished else None, "finished": info.finished}
