"""The user documentation: written for users, and its links lead somewhere.

docs/*.md (except docs/changelog.md, which is the place for history, and the transient
docs/_pending_*.md notes for the integrator) must not read as a
development log or point at files a repository reader cannot open; every relative link to a
docs page from docs/ or README.md must name an existing file and, with #anchor, an existing
heading (GitHub's slug rules). Each failure lists file:line for every offence.
"""

import re
import unicodedata
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"

# Wording that belongs in a changelog or points outside the repository.
FORBIDDEN = [
    (re.compile(r"\bissues?\s+\d", re.IGNORECASE), "an issue number"),
    (re.compile(r"\binterim\b", re.IGNORECASE), "'interim'"),
    (re.compile(r"\bseed-", re.IGNORECASE), "'seed-'"),
    # a section of a document cited by its capitalised name, where a docs/ page should be cited
    # (a chapter's Roman numeral, "Ch. II §4", is a source's structure, not such a citation)
    (re.compile(r"\b(?![IVXLC]+\b)[A-Z]{2,}\s*§"), "a '§' of a document that is not a docs/ page"),
    (re.compile(r"\.\./"), "a path out of the repository ('../')"),
]

# A Markdown file named anywhere on a page (name.md, with or without a folder).
MD_NAME = re.compile(r"(?<![\w/.-])(?P<name>(?:[\w.-]+/)*[\w-]+\.md)\b")

# A docs page named in a link or as plain text: docs/X.md, X.md inside docs/, optional #anchor.
LINK = re.compile(r"\]\(\s*(?P<target>[^)\s]+?\.md)(?:#(?P<anchor>[^)\s]*))?\s*\)")
PLAIN = re.compile(r"(?<![\w/.-])docs/(?P<target>[\w.-]+\.md)(?:#(?P<anchor>[\w\-%]+))?")


def _published():
    """docs pages a reader sees: not the helpers' docs/_pending_*.md notes for the integrator."""
    return sorted(p for p in DOCS.glob("*.md") if not p.name.startswith("_pending_"))


def user_pages():
    return [p for p in _published() if p.name != "changelog.md"]


def linking_pages():
    return _published() + [ROOT / "README.md"]


def _outside_code_fences(path):
    """(line number, text) of the lines outside ``` fences."""
    fenced = False
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        if not fenced:
            yield number, line


def github_slug(heading):
    """The anchor GitHub gives a heading: lower case, punctuation dropped, spaces → '-'."""
    text = re.sub(r"<[^>]+>", "", heading.strip()).lower()
    kept = []
    for char in text:
        category = unicodedata.category(char)
        if char in " -_" or category[0] in "LN" or category == "Mn":
            kept.append(char)
    return "".join(kept).replace(" ", "-")


def anchors(path):
    """Every heading anchor of a page, with GitHub's -1, -2 suffixes for repeated headings."""
    seen = {}
    found = set()
    for _, line in _outside_code_fences(path):
        match = re.match(r"#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not match:
            continue
        slug = github_slug(match.group(1))
        count = seen.get(slug, 0)
        found.add(slug if count == 0 else f"{slug}-{count}")
        seen[slug] = count + 1
    return found


def _where(path, number):
    return f"{path.relative_to(ROOT)}:{number}"


def test_user_pages_are_not_a_development_history():
    offences = []
    for page in user_pages():
        for number, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1):
            for pattern, what in FORBIDDEN:
                if pattern.search(line):
                    offences.append(f"{_where(page, number)}: {what}: {line.strip()[:100]}")
    assert not offences, "history or non-repository wording in docs (move it to docs/changelog.md):\n" + "\n".join(
        offences
    )


def test_every_markdown_file_a_page_names_is_in_the_repository():
    """A page may name only .md files a repository reader can open: a docs/ page or a file at
    the repository root (or the folder it gives)."""
    offences = []
    for page in linking_pages():
        for number, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1):
            for match in MD_NAME.finditer(line):
                name = match.group("name")
                candidates = [ROOT / name] if "/" in name else [DOCS / name, ROOT / name]
                if not any(path.is_file() for path in candidates):
                    offences.append(f"{_where(page, number)}: {name}: not a file in the repository")
    assert not offences, "pages name files a reader cannot open:\n" + "\n".join(offences)


def _resolve(page, target):
    """The file a relative link names, seen from page; None for a link out of the repository."""
    if re.match(r"[a-z]+://", target):
        return None
    if page.parent == DOCS and not target.startswith(("docs/", "../", "/")):
        return (DOCS / target).resolve()
    if target.startswith("/"):
        return (ROOT / target.lstrip("/")).resolve()
    if target.startswith("docs/"):
        return (ROOT / target).resolve()
    return (page.parent / target).resolve()


def test_links_to_docs_pages_lead_to_a_page_and_heading():
    offences = []
    anchor_cache = {}
    for page in linking_pages():
        for number, line in _outside_code_fences(page):
            references = [(m.group("target"), m.group("anchor")) for m in LINK.finditer(line)]
            references += [("docs/" + m.group("target"), m.group("anchor")) for m in PLAIN.finditer(line)]
            for target, anchor in dict.fromkeys(references):
                path = _resolve(page, target)
                if path is None:
                    continue
                if not path.is_file():
                    offences.append(f"{_where(page, number)}: {target}: no such file")
                    continue
                if anchor:
                    if path not in anchor_cache:
                        anchor_cache[path] = anchors(path)
                    if anchor.lower() not in anchor_cache[path]:
                        offences.append(f"{_where(page, number)}: {target}#{anchor}: no such heading")
    assert not offences, "broken links to docs pages:\n" + "\n".join(offences)


def test_the_slug_rule_matches_github():
    # Headings of this project's pages and the anchors GitHub gives them.
    assert github_slug("Data files (fmus/data/loader.py, schemas in fmus/data/schemas)") == (
        "data-files-fmusdataloaderpy-schemas-in-fmusdataschemas"
    )
    assert github_slug("WaysideCoder (WaysideCoder.fmu)") == "waysidecoder-waysidecoderfmu"
    assert github_slug("ALSN code timings (KPT-5, KPT-7)") == "alsn-code-timings-kpt-5-kpt-7"
    assert github_slug("Fire code and π/4-DQPSK") == "fire-code-and-π4-dqpsk"
    assert github_slug("Master algorithm (`orchestrator/master.py`)") == "master-algorithm-orchestratormasterpy"
