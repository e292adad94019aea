"""The protocol routes of the experimenter's API: list the protocols, upload one (web/protocols.py)."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Depends, HTTPException

from ..errors import StudyError
from ..studies.protocol_files import SHIPPED_PROTOCOLS, parse_protocol, shipped_protocol
from .api_models import ProtocolIn
from .protocols import protocol_summary, protocols_folder, read_uploaded
from .public_text import public_text
from .routes_experimenter import require_token

__all__ = ["router"]

router = APIRouter()


@router.get("/api/protocols")
def list_protocols(web: Any = Depends(require_token)) -> list[dict[str, Any]]:
    """The shipped protocols, then those uploaded to this server (by name)."""
    out = [protocol_summary(shipped_protocol(n), shipped=True) for n in SHIPPED_PROTOCOLS]
    for path in sorted(protocols_folder(web).glob("*.toml")):
        try:
            out.append(protocol_summary(read_uploaded(path, path.stem), shipped=False))
        except (StudyError, OSError, UnicodeDecodeError):  # a file put there by hand: not listed
            continue
    return out


@router.post("/api/protocols", status_code=201)
def upload_protocol(body: ProtocolIn, web: Any = Depends(require_token)) -> dict[str, Any]:
    """Check a protocol file's text and keep it under its name; 422 with one line, and nothing stored, if bad."""
    from .._atomic import write_text

    try:
        protocol = parse_protocol(body.text, body.filename)
        protocol.check_runnable()
    except StudyError as exc:
        raise HTTPException(422, detail=public_text(str(exc))) from None
    name = protocol.name
    if name in SHIPPED_PROTOCOLS:
        raise HTTPException(409, detail=(f"protocol {body.filename}: the name {name!r} is a shipped protocol's; "
                                         "give yours another name"))
    path = protocols_folder(web) / f"{name}.toml"
    if path.is_file():
        if path.read_bytes() != body.text.encode("utf-8"):
            raise HTTPException(409, detail=(
                f"protocol {body.filename}: another protocol named {name!r} is already on this server, and sessions "
                "name their protocol by its name only; give this one another name"))
    else:
        write_text(path, body.text, what="protocol file")
    return protocol_summary(protocol, shipped=False)
