"""The repository's tools package (tools/vibrofocus_tools) and the scripts over it."""

import ast
import importlib.util
from pathlib import Path

import numpy as np
import pytest

from vibrofocus_tools import findings, joint, markers

ROOT = Path(__file__).resolve().parents[2]
TOOLS = ROOT / "tools" / "vibrofocus_tools"


def _imports(path: Path) -> set[str]:
    """Every module ``path`` imports (absolute names; relative ones as ``.name``), anywhere in it."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = "." * node.level + (node.module or "")
            found |= {base} | {f"{base}.{a.name}" for a in node.names}
    return found


def test_the_tools_are_installed_from_this_checkout():
    spec = importlib.util.find_spec("vibrofocus_tools")
    assert spec is not None and Path(spec.origin).resolve() == TOOLS / "__init__.py"
    assert markers.ROOT == ROOT


def test_the_checks_stay_independent_of_the_analysis_and_of_the_fit():
    for module in ("findings", "baseline", "joint"):
        names = _imports(TOOLS / f"{module}.py")
        assert not {n for n in names if n.startswith(("vibrofocus.analysis", "vibrofocus.simulation.power",
                                                      "vibrofocus.simulation.paper", "vibrofocus.simulation.fitting"))}, module
    # joint is applied to an older commit's findings: nothing of vibrofocus at all.
    assert not {n for n in _imports(TOOLS / "joint.py") if n.startswith("vibrofocus")}
    assert not _imports(TOOLS / "__init__.py")


def test_no_script_imports_a_private_module_or_a_sibling_by_bare_name():
    scripts = sorted((ROOT / "scripts").glob("*.py"))
    names = {p.stem for p in scripts}
    for path in scripts:
        imported = _imports(path)
        private = [n for n in imported if n.startswith("vibrofocus") and any(
            part.startswith("_") and part != "__future__" for part in n.split("."))]
        assert not private, (path.name, private)
        assert not imported & names, (path.name, imported & names)
        source = path.read_text(encoding="utf-8")
        assert "sys.path" not in source, path.name


def _study(rng, inverse_shift_mm):
    """Cell means of one study (20 participants, 9 locations, 3 methods), inverse lowered by a shift."""
    error = 8.0 + rng.normal(0, 1.0, (20, 9, 3))
    error[:, :, 1] -= inverse_shift_mm
    count = 3.0 + rng.normal(0, 0.3, (20, 9, 3))
    count[:, :, 1] *= 0.8
    count_hit = 3.0 + rng.normal(0, 0.3, (20, 9, 3))
    return error, count, count_hit


def test_findings_read_a_clear_difference_and_its_absence():
    clear = findings.findings(*_study(np.random.default_rng(3), 3.0))
    assert clear["s1_inverse_lower"] and clear["s1_method_significant"]
    assert clear["s2_method"] and 0.15 < clear["s2_reduction"] < 0.25 and clear["s2_headline"]
    assert clear["s2_hit_n_location"] == 20
    none = findings.findings(*_study(np.random.default_rng(3), 0.0))
    assert not none["s1_inverse_lower"]
    # The joint findings hold only where each of their parts holds.
    for key, parts in joint.JOINT.items():
        assert clear[key] == all(clear[p] for p in parts)


def test_findings_table_counts_each_row_and_sets_the_baseline_beside_it():
    res = [findings.findings(*_study(np.random.default_rng(s), 3.0)) for s in range(2)]
    plain = findings.findings_table(res, 20).splitlines()
    assert plain[0] == "| finding | holds in |" and len(plain) == 2 + len(findings.ROWS) + 3
    assert plain[2 + [k for _, k in findings.ROWS].index("s1_inverse_lower")].endswith("| 2 of 2 |")
    base = {key: np.array([True, False]) for _, key in findings.ROWS}
    beside = findings.findings_table(res, 20, base).splitlines()
    assert beside[0].endswith("| baseline (c313a27) | paired McNemar p |")
    assert all(line.count("|") == 5 for line in beside)


def test_markers_replace_only_the_block_and_refuse_a_page_without_them(tmp_path):
    text = "a\n<!-- t:start -->\nold\n<!-- t:end -->\nb\n"
    assert markers.replace_between_markers(text, "t", "new", Path("p.md")) == "a\n<!-- t:start -->\nnew\n<!-- t:end -->\nb\n"
    with pytest.raises(SystemExit, match="no <!-- u:start -->"):
        markers.replace_between_markers(text, "u", "new", Path("p.md"))
    page = tmp_path / "p.md"
    page.write_text(text)
    markers.write_between_markers(page, "t", "new")
    assert "new" in page.read_text() and "old" not in page.read_text()


def test_the_documented_free_fit_recovery_tables_are_those_of_their_results():
    # scripts/free_fit_recovery.py --write puts each run's table between markers named after
    # its results file; the page must show what the file holds (a run resumed since, or a
    # table edited by hand, fails here).
    from vibrofocus_tools.recovery_tables import RESULTS, free_fit_block

    page = ROOT / "docs" / "fitting-hypotheses.md"
    text = page.read_text(encoding="utf-8")
    checked = 0
    for path in sorted(RESULTS.glob("free-*.jsonl")):
        if f"<!-- {path.stem}:start -->" in text:
            assert markers.replace_between_markers(text, path.stem, free_fit_block(path), page) == text, path.name
            checked += 1
    assert checked >= 2
