"""The docs never contradict the code: what README.md and docs/*.md say about presets,
versions, defaults, windows and level rules is read against the constants themselves; links
resolve; no internal issue numbers; docs/web.md names every control of the experimenter page.

Each rule is a function over a page's text returning what it finds wrong, so the rules
themselves are tested on planted stale statements (a check that finds nothing on a clean
page must find those).
"""

from __future__ import annotations

import re
from html.parser import HTMLParser
from pathlib import Path

import pytest

import vibrofocus
from vibrofocus.defaults import N_SAMPLES, STUDY_METHODS
from vibrofocus.rendering.registry import available_methods
from vibrofocus.simulation.perception import MODEL_VERSION, STUDY_SKIN
from vibrofocus.skin import DEFAULT_SKIN, SKIN_PRESETS
from vibrofocus.studies.engine import CalibrationRenderer
from vibrofocus.studies.protocol import DEFAULT_LEVELS, LEVEL_RULES

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PACKAGE = Path(vibrofocus.__file__).parent

#: docs/changelog.md only includes CHANGELOG.md, which keeps the project's history.
PAGES = [ROOT / "README.md"] + sorted(p for p in DOCS.glob("*.md") if p.name not in ("changelog.md", "cli.md"))


PRESETS = tuple(SKIN_PRESETS)
_NAME = r"[a-z][a-z0-9_.-]*"


def _rel(path: Path) -> str:
    return path.relative_to(ROOT).as_posix()


def _sentences(text: str) -> list[str]:
    """Rough sentences: split at '. ' and blank lines, joined over line breaks."""
    flat = re.sub(r"\s*\n\s*", " ", text)
    return re.split(r"(?<=[.;:!?])\s+(?=[A-Z*`(|-])|\s\|\s", flat)


# --- the rules -----------------------------------------------------------------------------

def unknown_skin_presets(text: str) -> list[str]:
    """Skin presets named (`X` skin, `X` arm, --skin X, skin="X") that the code does not have."""
    found = set(re.findall(rf"`({_NAME})` (?:skin|arm)\b", text))
    found |= set(re.findall(rf"skin=[\"']({_NAME})[\"']", text))
    for group in re.findall(r"`[^`\n]*--skin[ =]([a-z][a-z0-9|_.-]*)[^`\n]*`", text):
        found |= {g for g in group.split("|") if g and g.upper() != g}
    found -= {"NAME", "PRESET"}
    return sorted(f"skin preset {name!r} is not one of {PRESETS}" for name in found if name not in PRESETS)


def wrong_default_skin(text: str) -> list[str]:
    """A preset called the default that is not :data:`DEFAULT_SKIN`."""
    wrong = []
    for name in re.findall(r"\*{0,2}`([a-z][a-z0-9_-]*)`\*{0,2} \((?:the )?default\b", text):
        if name in PRESETS and name != DEFAULT_SKIN:
            wrong.append(f"`{name}` called the default skin; the code's is {DEFAULT_SKIN!r}")
    return wrong


def wrong_study_skin(text: str) -> list[str]:
    """The skin said to be the simulated participants' (or their model's) that is not STUDY_SKIN."""
    wrong = []
    pattern = re.compile(r"(?:\buses?|\bused|fitted on|fitted to|feels?)(?: only)? (?:the |on the )?"
                         r"`([a-z][a-z0-9_-]*)` (?:skin|arm|preset)")
    for sentence in _sentences(text):
        about = re.search(r"simulated participants|perceptual model|STUDY_SKIN|[Tt]he model was", sentence)
        if not about:
            continue
        names = pattern.findall(sentence)
        names += re.findall(r"`([a-z][a-z0-9_-]*)` (?:skin |arm )?\(`STUDY_SKIN`\)", sentence)
        names += re.findall(r"`([a-z][a-z0-9_-]*)``?, the (?:skin|arm) the (?:perceptual )?model", sentence)
        for name in names:
            if name in PRESETS and name != STUDY_SKIN:
                wrong.append(f"simulated participants said to use `{name}`; STUDY_SKIN is {STUDY_SKIN!r}: "
                             f"{sentence[:160]}")
    return wrong


def wrong_model_version(text: str) -> list[str]:
    """'model vX.Y' / 'perceptual model (vX)' that is not MODEL_VERSION."""
    wrong = []
    for version in re.findall(r"\bmodel \(?v(\d+(?:\.\d+)*)\b", text):
        full = MODEL_VERSION.split(".")
        said = version.split(".")
        if said != full[:len(said)]:
            wrong.append(f"model v{version}; the code's MODEL_VERSION is {MODEL_VERSION}")
    return wrong


def wrong_study_methods(text: str) -> list[str]:
    """'N methods (a, b, c)' for a study's design, and method names in such lists, against the code."""
    wrong = []
    numbers = {"two": 2, "three": 3, "four": 4, "five": 5, "six": 6}
    for count, names in re.findall(r"\b(\d+|two|three|four|five|six) methods \(([a-z_, ]+)\)", text):
        listed = tuple(n.strip() for n in names.replace(" and ", ",").split(",") if n.strip())
        unknown = [n for n in listed if n not in available_methods()]
        if unknown:
            wrong.append(f"unknown methods {unknown} in '{count} methods ({names})'")
        if int(numbers.get(count, count)) != len(listed):
            wrong.append(f"'{count} methods' lists {len(listed)}: {names}")
        if listed != STUDY_METHODS:
            wrong.append(f"study methods ({names}); the code's STUDY_METHODS are {', '.join(STUDY_METHODS)}")
    return wrong


def wrong_windows(text: str) -> list[str]:
    """The session's design window: its start (the calibration's own resolution) and its cap."""
    wrong = []
    for n in re.findall(r"own resolution \((\d+) samples\)", text):
        if int(n) != N_SAMPLES:
            wrong.append(f"own resolution {n} samples; the default calibration resolution is {N_SAMPLES}")
    for n in re.findall(r"window (?:is )?doubled \(up to (\d+)\s+samples\)", text):
        if int(n) != CalibrationRenderer.MAX_SAMPLES:
            wrong.append(f"window doubled up to {n} samples; the code's cap is {CalibrationRenderer.MAX_SAMPLES}")
    for n in re.findall(r"(?:design window|window) of (\d+) samples by default", text):
        if int(n) != N_SAMPLES:
            wrong.append(f"default window {n}; N_SAMPLES is {N_SAMPLES}")
    return wrong


def wrong_level_rules(text: str) -> list[str]:
    """Level rules that do not exist, and a default level rule that is not DEFAULT_LEVELS."""
    wrong = []
    named = re.findall(r"--levels[ =]`?([a-z][a-z0-9|_-]*)", text)
    named += re.findall(r"levels=[\"']([^\"']+)[\"']", text)
    for group in named:
        for rule in group.split("|"):
            if rule and rule not in LEVEL_RULES:
                wrong.append(f"level rule {rule!r} is not one of {LEVEL_RULES}")
    defaults = re.findall(r"by default \(`(?:--)?levels[= ][\"']?([a-z-]+)", text)
    defaults += re.findall(r"`(?:--)?levels[= ][\"']?([a-z-]+)[\"']?`,? \((?:the )?default\b", text)
    defaults += re.findall(r"--levels ([a-z-]+)` \(the default", text)
    for rule in defaults:
        if rule != DEFAULT_LEVELS:
            wrong.append(f"{rule!r} called the default level rule; DEFAULT_LEVELS is {DEFAULT_LEVELS!r}")
    return wrong


def issue_numbers(text: str) -> list[str]:
    """Internal issue numbers ("issue 24", "issues 16/32", "issue #5")."""
    return [m.group(0) for m in re.finditer(r"\b[Ii]ssues? #?\d+", text)]


#: Package text (docstrings, help, templates, data notes) read by the same rules.
def _user_facing_sources() -> list[Path]:
    kinds = ("*.py", "*.md", "*.html", "*.js", "*.txt")
    return sorted(p for kind in kinds for p in PACKAGE.rglob(kind))


RULES = (unknown_skin_presets, wrong_default_skin, wrong_study_skin, wrong_model_version, wrong_study_methods,
         wrong_windows, wrong_level_rules)


# --- the rules can fail ----------------------------------------------------------------------

STALE = {
    unknown_skin_presets: "Run it with `--skin layered-v0` or on the `soft` skin.",
    wrong_default_skin: "- **`voigt-fit`** (the default), `low` and `high` are presets.",
    wrong_study_skin: "The simulated participants still use the `voigt-fit` arm. Their perceptual model was "
                      "fitted on it. Skin preset of the participants' forearms (default ``voigt-fit``, the skin the "
                      "perceptual model was fitted on).",
    wrong_model_version: "Reports say simulated participants: model v2.1, not data.",
    wrong_study_methods: "- **Study 1:** 3 methods (funneling, inverse, time_reversal) × 9 locations.",
    wrong_windows: "on one design window from the calibration: its own resolution\n(8192 samples), then the "
                   "window doubled (up to 16384\nsamples).",
    wrong_level_rules: "Both studies play the paper's levels by default (`levels=\"equal-peak\"`); `--levels loud`.",
    issue_numbers: "(see the closing note of issue 32)",
}


@pytest.mark.parametrize("rule", list(STALE), ids=lambda r: r.__name__)
def test_each_rule_catches_a_planted_stale_statement(rule):
    assert rule(STALE[rule]), f"{rule.__name__} missed: {STALE[rule]}"


def test_rules_accept_what_the_code_says():
    """The same statements, true to the code, pass (so a rule does not fail on everything)."""
    true = (f"Run it with `--skin {DEFAULT_SKIN}` on the `{PRESETS[-1]}` skin. "
            f"- **`{DEFAULT_SKIN}`** (the default) is a preset. "
            f"The simulated participants use the `{STUDY_SKIN}` arm (`STUDY_SKIN`). "
            f"Reports say simulated participants: model v{MODEL_VERSION}, not data. "
            f"- **Study 1:** {len(STUDY_METHODS)} methods ({', '.join(STUDY_METHODS)}) × 9 locations. "
            f"its own resolution ({N_SAMPLES} samples), then the window doubled (up to "
            f"{CalibrationRenderer.MAX_SAMPLES} samples). "
            f"Both studies play the paper's levels by default (`levels=\"{DEFAULT_LEVELS}\"`).")
    for rule in RULES:
        assert rule(true) == [], rule.__name__


# --- the docs -------------------------------------------------------------------------------

@pytest.mark.parametrize("page", PAGES, ids=_rel)
def test_docs_state_what_the_code_has(page):
    text = page.read_text(encoding="utf-8")
    problems = [p for rule in RULES for p in rule(text)]
    assert not problems, f"{_rel(page)}:\n" + "\n".join(problems)


@pytest.mark.parametrize("part", ["docstrings and help"])
def test_package_text_states_what_the_code_has(part):
    problems = [f"{_rel(path)}: {p}" for path in _user_facing_sources()
                for rule in RULES for p in rule(path.read_text(encoding="utf-8"))]
    assert not problems, "\n".join(problems)


def test_no_internal_issue_numbers_in_docs_help_or_package():
    hits = []
    for path in PAGES + _user_facing_sources():
        for lineno, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            hits += [f"{_rel(path)}:{lineno}: {hit}" for hit in issue_numbers(line)]
    assert not hits, "internal issue numbers in user-facing text:\n" + "\n".join(hits)


#: A citation of a file the repository does not have: the specification the project started
#: from, or anything beside the checkout. Docs and code cite the docs pages instead.
_OUTSIDE = re.compile(r"\bSPEC(?:\.md|\s*§)|\.\./shared\b|(?<![\w./-])shared/\w")


def _repository_text() -> list[Path]:
    """The repository's own text: package, docs, tests, benchmarks, examples, scripts, tools
    and top-level files."""
    files = [ROOT / name for name in ("README.md", "DEVELOPING.md", "pyproject.toml", ".ci/run")]
    for folder, patterns in (("src", ("*.py", "*.md", "*.html", "*.toml")), ("docs", ("*.md", "*.py")),
                             ("tests", ("*.py", "*.md")), ("benchmarks", ("*.py",)), ("examples", ("*.py", "*.rst")),
                             ("scripts", ("*.py", "*.sh")), ("tools", ("*.py",))):
        for pattern in patterns:
            files += sorted((ROOT / folder).rglob(pattern))
    return [f for f in files if f.is_file()]


def test_the_repository_cites_no_file_outside_it():
    hits = [f"{path.relative_to(ROOT)}:{lineno}: {line.strip()}"
            for path in _repository_text()
            for lineno, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1) if _OUTSIDE.search(line)]
    assert not hits, "cite the docs pages, not a file outside the repository:\n" + "\n".join(hits)


def test_the_outside_citation_check_can_fail():
    spec, shared = "SPEC", "shared/"  # apart, so that this file passes the check above
    for line in (f"designs ({spec} §2).", f"Read `../{shared}{spec}.md` first.", f"see {shared}PAPER.md"):
        assert _OUTSIDE.search(line), line
    for line in ('(docs/method.md, "Rendering methods")', "SPECTRUM", "a shared/ folder", "the shared one"):
        assert not _OUTSIDE.search(line), line


# --- links ----------------------------------------------------------------------------------

_LINK = re.compile(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)|<img [^>]*src=\"([^\"]+)\"")
_FENCE = re.compile(r"^(```|~~~).*?^\1", re.S | re.M)


def _slug(heading: str) -> str:
    """GitHub's and MyST's heading anchor: lower case, punctuation dropped, spaces to '-'."""
    text = re.sub(r"`|\*\*|\*|_(?=\w)|(?<=\w)_", "", heading.strip()).lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(text: str, max_level: int = 6) -> set[str]:
    """The heading anchors of a Markdown page (headings up to ``max_level``)."""
    text = _FENCE.sub("", text)
    return {_slug(m.group(2)) for m in re.finditer(r"^(#{1,6})\s+(.+?)\s*#*\s*$", text, re.M)
            if len(m.group(1)) <= max_level}


def generated_pages() -> set[str]:
    """Pages docs/conf.py writes at build time (``DOCS / "cli.md"``)."""
    return set(re.findall(r'DOCS / "([^"]+)"', (DOCS / "conf.py").read_text(encoding="utf-8")))


def broken_links(page: Path, text: str | None = None) -> list[str]:
    """Relative links and image sources of ``page`` whose file or anchor does not exist."""
    text = _FENCE.sub("", page.read_text(encoding="utf-8") if text is None else text)
    generated = generated_pages() if page.parent == DOCS else set()
    # MyST makes anchors for headings up to level 3 (conf.py: myst_heading_anchors); GitHub for all.
    level = 3 if page.parent == DOCS else 6
    broken = []
    for match in _LINK.finditer(text):
        target = match.group(1) or match.group(2)
        if re.match(r"[a-z][a-z0-9+.-]*:", target) or target.startswith("//"):
            continue  # http(s), mailto: no network here
        path, _, anchor = target.partition("#")
        if path and path in generated:
            # A page only the build makes is a broken link on GitHub and in a checkout.
            broken.append(f"{target}: made only by the docs build; name the command instead")
            continue
        dest = (page.parent / path).resolve() if path else page
        if not dest.exists():
            broken.append(f"{target}: no such file")
            continue
        if anchor and dest.suffix == ".md":
            if anchor not in anchors(dest.read_text(encoding="utf-8"), level):
                broken.append(f"{target}: no heading with that anchor in {dest.name}")
    return broken


@pytest.mark.parametrize("page", PAGES, ids=_rel)
def test_relative_links_and_anchors_resolve(page):
    broken = broken_links(page)
    assert not broken, f"{_rel(page)}:\n" + "\n".join(broken)


def test_the_docs_checks_need_no_browser(request):
    """An argument named like a fixture (``page``, a page of the docs) marks no test as a
    browser test (tests/conftest.py marks by the fixtures a test uses): these checks run in
    the quick loop and in parallel."""
    names = ("test_docs_state_what_the_code_has", "test_relative_links_and_anchors_resolve")
    checks = [item for item in request.session.items if getattr(item, "originalname", None) in names]
    if not checks:
        pytest.skip("the docs checks are not collected in this run")
    assert not [item.nodeid for item in checks if item.get_closest_marker("browser")]


def test_the_link_check_can_fail(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("# Title here\n\n## A `code` section\n", encoding="utf-8")
    text = ("[ok](#a-code-section) [ok too](page.md#title-here) [gone](nowhere.md) [bad anchor](#no-such) "
            '![img](missing.png) <img src="missing2.png"> [web](https://example.org/x)\n')
    broken = broken_links(page, text)
    assert broken == ["nowhere.md: no such file", "#no-such: no heading with that anchor in page.md",
                      "missing.png: no such file", "missing2.png: no such file"]


# --- the experimenter page and docs/web.md -----------------------------------------------------

class _Controls(HTMLParser):
    """Visible names of the template's controls: buttons, link buttons, labels, card titles,
    and text fields named only by a placeholder."""

    def __init__(self) -> None:
        super().__init__()
        self.names: list[str] = []
        self._open: list[tuple[str, list[str]]] = []
        self._skip = 0  # inside a <select> (its options are values, not the control's name)

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "select":
            self._skip += 1
        if tag in ("button", "label", "h2") or (tag == "a" and "button" in (a.get("class") or "")):
            self._open.append((tag, []))
        if tag == "input" and a.get("placeholder") and not any(t == "label" for t, _ in self._open):
            self.names.append(a["placeholder"].split(",")[0])

    def handle_endtag(self, tag):
        if tag == "select":
            self._skip -= 1
        if self._open and self._open[-1][0] == tag:
            _, parts = self._open.pop()
            name = " ".join("".join(parts).split())
            if name and "{" not in name:
                self.names.append(name)

    def handle_data(self, data):
        if self._open and not self._skip:
            self._open[-1][1].append(data)


def experimenter_controls() -> list[str]:
    parser = _Controls()
    parser.feed((PACKAGE / "web" / "templates" / "experimenter.html").read_text(encoding="utf-8"))
    return list(dict.fromkeys(parser.names))


def test_web_md_names_every_control_of_the_experimenter_page():
    controls = experimenter_controls()
    # The parser must see the page's controls at all (a template rewrite would show here).
    assert {"Emergency stop", "Seed", "simulated (the model answers)", "Plan session"} <= set(controls)
    doc = " ".join((DOCS / "web.md").read_text(encoding="utf-8").split()).lower()
    missing = [c for c in controls if f"*{c.lower()}*" not in doc]
    assert not missing, f"docs/web.md does not name (in *italics* or **bold**) these controls: {missing}"
