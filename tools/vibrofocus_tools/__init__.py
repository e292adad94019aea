"""The repository's own tools: the independent check of the paper's findings, the docs' tables.

Not part of vibrofocus's API: these modules serve the scripts in ``scripts/`` (thin command
lines over them) and the tests, and read and write files of a checkout (docs pages,
``scripts/fits/``), so they are meant for an editable install (``pip install -e .``).

:mod:`.findings`
    The paper's findings in one simulated study, analysed HERE with pingouin and scipy
    only: independent of :mod:`vibrofocus.analysis` and of the statistics the fit
    optimizes (``scripts/check_findings.py``).
:mod:`.joint`
    Findings made of other findings; imports nothing of vibrofocus (it is applied to an
    older commit's findings too, ``scripts/baseline_findings.py``).
:mod:`.baseline`
    Issue 42's baseline (the participants of commit c313a27) and the paired test against it.
:mod:`.markers`
    The generated blocks of the docs pages.
:mod:`.participants_docs`
    The generated tables of docs/simulated-participants.md.
:mod:`.hypotheses_tables`
    The paper's findings under every hypothesis (``scripts/hypotheses_table.py``).
:mod:`.selection_rules`
    Other Study 2 selection rules on the same percepts (``scripts/selection_rules.py``).
:mod:`.reference_designs`
    The drives of every built-in method, for the regression test of ``render``.

This ``__init__`` imports nothing, so :mod:`.joint` loads without vibrofocus.
"""
