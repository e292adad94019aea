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
    """
    with user_errors():
        from .._atomic import allow_overwrite, protect
        from ..studies.bids import export_bids

        protect(source, "study database or trials file")
        allow_overwrite(force)
        counts = export_bids(source, bids, force=force)
        into = "added to the existing BIDS dataset" if counts["merged"] else "to the BIDS dataset"
        typer.echo(f"wrote {counts['events']} trials of {counts['participants']} participant(s) {into} {bids}")
        if counts["kept"]:
            typer.echo(f"kept the dataset's own {' and '.join(counts['kept'])}")
