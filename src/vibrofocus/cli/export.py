"""``vibrofocus export --bids DIR``: a study database or a trials CSV as a BIDS behavioural dataset."""

from __future__ import annotations

from pathlib import Path

import typer

from ._command import command
from ._errors import user_errors

_FORCE_HELP = ("Replace files in the dataset at the paths the export writes that vibrofocus did not write (or "
               "that were edited since); without it they are refused and nothing changes.")


@command("export", epilog="Example: vibrofocus export study.sqlite --bids bids/  (then open bids/ with pybids).")
def export_command(
    source: Path = typer.Argument(..., help="A study database (SQLite) or a trials CSV.", show_default=False),
    bids: Path = typer.Option(..., "--bids", help="The BIDS dataset folder to write (its parent must exist).",
                              show_default=False),
    force: bool = typer.Option(False, "--force", help=_FORCE_HELP),
    author: list[str] = typer.Option(None, "--author", show_default=False,
                                     help="An author of the dataset (dataset_description.json Authors); repeat "
                                          "for each, in order."),
    license_: str = typer.Option(None, "--license", show_default=False,
                                 help="The dataset's license (dataset_description.json License), e.g. CC0 or "
                                      "CC-BY-4.0."),
    institution: str = typer.Option(None, "--institution", show_default=False,
                                    help="The institution that ran the study (InstitutionName, in every events "
                                         "sidecar)."),
    metadata: Path = typer.Option(None, "--metadata", show_default=False,
                                  help="A JSON template of BIDS metadata: Name, Authors, License, Funding, "
                                       "EthicsApprovals, ... and InstitutionName, InstitutionAddress, "
                                       "InstitutionalDepartmentName (a lab's dataset_description.json reads too). "
                                       "--author, --license and --institution override it; what the dataset "
                                       "holds already is kept unless given."),
) -> None:
    """Export the localization studies as a BIDS behavioural dataset.

    Writes dataset_description.json, participants.tsv/.json and, per participant and study,
    sub-<id>/beh/sub-<id>_task-localization<1|2>_events.tsv with its JSON sidecar: one row per
    answered trial. A new DIR is built beside it and put in place as a whole. Into an
    existing dataset (EEG, MRI, another study's export) the behavioural files are added:
    only files vibrofocus wrote there (listed with their hashes in DIR/.vibrofocus-bids.json)
    are replaced, participants.tsv/.json are merged keeping every column and row of
    yours, and nothing is deleted; a file of yours where the export would write is
    refused unless --force. Simulated participants are labelled as a model.

    Each study session is a BIDS session (sub-<id>/ses-<session>/beh/...); onset counts
    from the session's first stimulus on the host's monotonic clock (a trials CSV with
    onset_host_s has it too). Authors, License and the institution come from the options
    or a --metadata template, and a re-export keeps what the dataset holds; docs/bids.md
    lists the validator's warnings that remain for behaviour-only data.
    """
    with user_errors():
        from .._atomic import allow_overwrite, protect
        from ..studies.bids import export_bids

        from ..io.bids import read_bids_metadata_file

        protect(source, "study database or trials file")
        allow_overwrite(force)
        meta = read_bids_metadata_file(metadata) if metadata is not None else {}
        meta.update({k: v for k, v in (("Authors", list(author) if author else None), ("License", license_),
                                       ("InstitutionName", institution)) if v is not None})
        counts = export_bids(source, bids, force=force, metadata=meta)
        into = "added to the existing BIDS dataset" if counts["merged"] else "to the BIDS dataset"
        typer.echo(f"wrote {counts['events']} trials of {counts['participants']} participant(s) {into} {bids}")
        if counts["kept"]:
            typer.echo(f"kept the dataset's own {' and '.join(counts['kept'])}")
