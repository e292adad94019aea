"""``vibrofocus export --bids DIR``: a study database or a trials CSV as a BIDS behavioural dataset."""

from __future__ import annotations

from pathlib import Path

import typer

from ._command import command
from ._errors import user_errors


@command("export", epilog="Example: vibrofocus export study.sqlite --bids bids/  (then open bids/ with pybids).")
def export_command(
    source: Path = typer.Argument(..., help="A study database (SQLite) or a trials CSV.", show_default=False),
    bids: Path = typer.Option(..., "--bids", help="The BIDS dataset folder to write (its parent must exist).",
                              show_default=False),
) -> None:
    """Export the localization studies as a BIDS behavioural dataset.

    Writes dataset_description.json, participants.tsv/.json and, per participant and study,
    sub-<id>/beh/sub-<id>_task-localization<1|2>_events.tsv with its JSON sidecar: one row per
    answered trial. The dataset is built beside DIR and put in place as a whole; files of
    your own in DIR are left alone. Simulated participants are labelled as a model.
    """
    with user_errors():
        from .._atomic import protect
        from ..studies.bids import export_bids

        protect(source, "study database or trials file")
        counts = export_bids(source, bids)
        typer.echo(f"wrote {counts['events']} trials of {counts['participants']} participant(s) to the BIDS dataset {bids}")
