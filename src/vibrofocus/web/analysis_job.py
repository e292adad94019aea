"""The web app's analysis, run in a child process.

The analysis (pingouin, matplotlib, pandas) holds the interpreter for seconds. Run in
the server's own process it would compete, through the GIL, with the thread that times
cues and stimuli of a live session; in a spawned child it cannot. The child calls the
same function as ``vibrofocus analyze`` (:func:`vibrofocus.analysis.report_trials_file`),
not the command line.
"""

from __future__ import annotations

import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

__all__ = ["analyse_in_child", "report_lines"]

_KIND_WORDS = {"people": "people on hardware", "simulated": "simulated participants",
               "rehearsals": "rehearsals on the simulated rig"}


def report_lines(trials: str, out_dir: str, kind: str = "people") -> list[str]:
    """Analyse ``trials`` into ``out_dir`` and return the job log's lines (runs in the child).

    Parameters
    ----------
    trials : str
        A trials CSV (docs/file-formats.md, trials file).
    out_dir : str
        The report folder.
    kind : {"people", "simulated", "rehearsals"}
        Which participants to analyse (:func:`vibrofocus.analysis.report_trials_file`).

    Returns
    -------
    list of str
        What was analysed, excluded and written.
    """
    import os

    from ..analysis import report_trials_file

    # From inside the report folder, with relative paths: the report names its source
    # "trials.csv", never the account's folders (it is served to the browser). The child
    # is a process of its own, so changing its folder touches nothing else.
    os.chdir(out_dir)
    result, paths = report_trials_file(Path(os.path.relpath(trials, out_dir)), Path("."), kind=kind)
    lines = [f"analysed {result.n_trials} rows ({_KIND_WORDS[kind]})"]
    lines += [f"excluded {e.participant}: {e.reason}" for e in result.exclusions.itertuples(index=False)]
    lines += [f"note: {w}" for w in result.warnings]
    lines.append(f"wrote {', '.join(p.name for p in paths.values())}")
    return lines


def analyse_in_child(trials: Path, out_dir: Path, *, kind: str = "people") -> list[str]:
    """:func:`report_lines` in a fresh spawned process; blocks until it is done.

    Parameters
    ----------
    trials : Path
        A trials CSV.
    out_dir : Path
        The report folder.
    kind : {"people", "simulated", "rehearsals"}
        Which participants to analyse.

    Returns
    -------
    list of str
        The job log's lines.

    Raises
    ------
    VibrofocusError
        What the analysis raised for a bad trials file (re-raised from the child).
    concurrent.futures.process.BrokenProcessPool
        If the child died.
    """
    # spawn, not fork: the server has threads (a forked child would inherit held locks).
    with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn")) as pool:
        return pool.submit(report_lines, str(trials), str(out_dir), kind).result()
