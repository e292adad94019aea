"""``vibrofocus export``: a study database or a trials CSV as a BIDS behavioural dataset (``--bids DIR``), or a
calibration's transfer matrix as a SOFA file (``--sofa OUT.sofa``)."""

from __future__ import annotations

from pathlib import Path

import typer

from ._command import command
from ._errors import user_errors

_FORCE_HELP = ("Replace files in the dataset at the paths the export writes that vibrofocus did not write (or "
               "that were edited since); without it they are refused and nothing changes.")


@command("export", epilog="Examples: vibrofocus export study.sqlite --bids bids/  (then open bids/ with pybids);  "
                          "vibrofocus export P01.nc --sofa P01.sofa --band-only  (then open it with sofar or pyfar).")
def export_command(
    source: Path = typer.Argument(..., help="A study database (SQLite) or a trials CSV (with --bids); a calibration "
                                            "file (with --sofa).", show_default=False),
    bids: Path = typer.Option(None, "--bids", help="The BIDS dataset folder to write (its parent must exist).",
                              show_default=False),
    sofa: Path = typer.Option(None, "--sofa", help="The SOFA file (AES69 GeneralTF-E) to write the calibration's "
                                                   "transfer matrix to; needs pip install 'vibrofocus[sofa]'.",
                              show_default=False),
    band_only: bool = typer.Option(False, "--band-only", help="With --sofa: only the calibrated band, with the "
                                                              "coherence beside H (the variable Coherence)."),
    force: bool = typer.Option(False, "--force", help=_FORCE_HELP),
    author: list[str] = typer.Option(None, "--author", show_default=False, metavar="<str>",
                                     help="An author of the dataset (dataset_description.json Authors); repeat "
                                          "for each, in order. With --sofa: GLOBAL_AuthorContact."),
    license_: str = typer.Option(None, "--license", show_default=False,
                                 help="The dataset's license (dataset_description.json License; with --sofa "
                                      "GLOBAL_License), e.g. CC0 or CC-BY-4.0."),
    institution: str = typer.Option(None, "--institution", show_default=False,
                                    help="The institution that ran the study (InstitutionName, in every events "
                                         "sidecar; with --sofa GLOBAL_Organization)."),
    metadata: Path = typer.Option(None, "--metadata", show_default=False,
                                  help="A JSON template of BIDS metadata: Name, Authors, License, Funding, "
                                       "EthicsApprovals, ... and InstitutionName, InstitutionAddress, "
                                       "InstitutionalDepartmentName (a lab's dataset_description.json reads too). "
                                       "--author, --license and --institution override it; what the dataset "
                                       "holds already is kept unless given."),
    session_label: list[str] = typer.Option(None, "--session-label", show_default=False, metavar="ID=LABEL",
                                            help="With --bids: file study session ID (the database's id) as "
                                                 "ses-LABEL, beside the lab's own sessions (e.g. 3=01); repeat "
                                                 "for each. Others keep their id."),
) -> None:
    """Export the localization studies as a BIDS behavioural dataset, or a calibration as a SOFA file.

    Writes dataset_description.json, participants.tsv/.json and, per participant and study
    session, sub-<id>/ses-<n>/beh/..._task-localization<1|2>_events.tsv with its JSON
    sidecar: one row per answered trial. A new DIR is built beside it and put in place as a whole. Into an
    existing dataset (EEG, MRI, another study's export) the behavioural files are added:
    only files vibrofocus wrote there (listed with their hashes in DIR/.vibrofocus-bids.json)
    are replaced, participants.tsv/.json are merged keeping every column and row of
    yours, and nothing is deleted; a file of yours where the export would write is
    refused unless --force. Simulated participants are labelled as a model.

    A source without sessions (a trials CSV without a session column) has no ses-. Onset counts
    from the session's first stimulus on the host's monotonic clock (a trials CSV with
    onset_host_s has it too). Authors, License and the institution come from the options
    or a --metadata template, and a re-export keeps what the dataset holds; docs/bids.md
    lists the validator's warnings that remain for behaviour-only data.

    With --sofa, SOURCE is a calibration file and its transfer matrix H (m/V) is written
    as a SOFA GeneralTF-E file (AES69-2020/2022, SOFA 2.x): receivers are the skin points,
    emitters the actuators, DateCreated the calibration's date (docs/sofa.md).
    """
    with user_errors():
        from .._atomic import allow_overwrite, protect
        from ..errors import ValidationError

        if (bids is None) == (sofa is None):
            raise ValidationError("give one of --bids DIR (a study database or trials CSV) or --sofa OUT.sofa (a "
                                  "calibration)")
        if sofa is not None:
            if metadata is not None:
                raise ValidationError("--metadata is a BIDS template; with --sofa give --author, --institution and "
                                      "--license")
            from ..calibration import export_sofa, load_calibration

            protect(source, "calibration file")
            allow_overwrite(force)
            cal = load_calibration(source)
            export_sofa(cal, sofa, force=force, band_only=band_only, author_contact="; ".join(author or []),
                        organization=institution or "", license=license_)
            what = (f"the calibrated band {cal.band[0]:g}-{cal.band[1]:g} Hz with its coherence" if band_only
                    else f"0-{cal.fs / 2:g} Hz")
            typer.echo(f"wrote the transfer matrix of {cal.participant_id} ({what}) to {sofa}")
            return
        if band_only:
            raise ValidationError("--band-only is a SOFA option (--sofa)")
        protect(source, "study database or trials file")
        allow_overwrite(force)
        _export_bids(source, bids, force=force, metadata=metadata, author=author, license_=license_,
                     institution=institution, session_label=session_label)


def _export_bids(source: Path, bids: Path, *, force: bool, metadata: Path | None, author: list[str] | None,
                 license_: str | None, institution: str | None, session_label: list[str] | None) -> None:
    """``export --bids``: the options as metadata and session labels, the export, what it did."""
    from ..io.bids import read_bids_metadata_file
    from ..studies.bids import export_bids

    meta = read_bids_metadata_file(metadata) if metadata is not None else {}
    meta.update({k: v for k, v in (("Authors", list(author) if author else None), ("License", license_),
                                   ("InstitutionName", institution)) if v is not None})
    counts = export_bids(source, bids, force=force, metadata=meta, session_labels=_session_labels(session_label or []))
    into = "added to the existing BIDS dataset" if counts["merged"] else "to the BIDS dataset"
    typer.echo(f"wrote {counts['events']} trials of {counts['participants']} participant(s) {into} {bids}")
    if counts["kept"]:
        typer.echo(f"kept the dataset's own {' and '.join(counts['kept'])}")
        given = [option for option, value in (("--author", author), ("--license", license_)) if value]
        if "dataset_description.json" in counts["kept"] and given:
            # vibrofocus never edits a file it did not write: the lab's description stays as it is.
            typer.echo(f"note: {' and '.join(given)} not applied: the dataset's dataset_description.json is "
                       "its own (vibrofocus did not write it); add them there")


def _session_labels(pairs: list[str]) -> dict[int, str]:
    """``--session-label ID=LABEL`` options as {id: label} (checked by export_bids)."""
    from ..errors import ValidationError

    out: dict[int, str] = {}
    for pair in pairs:
        key, sep, label = pair.partition("=")
        if not sep or not key.strip().isdigit():
            raise ValidationError(f"--session-label {pair!r}: give the session's database id and its label, e.g. 3=01")
        if int(key) in out:
            raise ValidationError(f"--session-label names session {int(key)} twice")
        out[int(key)] = label.strip()
    return out
