"""The user documentation: written for users, and its links lead somewhere.

docs/*.md (except docs/changelog.md, which is the place for history, and the transient
docs/_pending_*.md notes for the integrator) must not read as a
development log or point at files a repository reader cannot open; every relative link to a
docs page from docs/ or README.md must name an existing file and, with #anchor, an existing
heading (GitHub's slug rules). Each failure lists file:line for every offence.

History has one place, docs/changelog.md: README.md and the other pages name none of this
repository's commits (a commit of another repository, cited as a source, is fine), number no
"item N" of a list of changes, and carry no date (docs/sources.md may: a source's
publication date is part of its citation).
"""

import re
import shutil
import subprocess
import unicodedata
from pathlib import Path

import pytest

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

# A word that may be an abbreviated or full commit id: 7 to 40 lower-case hex digits with at
# least one digit and one letter (not a decimal figure, not a word such as "defaced").
HEX_WORD = re.compile(r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}\b")
# An entry of a numbered list of changes: "item 23", "items 19 to 22".
ITEM_NUMBER = re.compile(r"\bitems?\s+\d+", re.IGNORECASE)
# A calendar date, 2026-11-24.
DATE = re.compile(r"\b\d{4}-[01]\d-[0-3]\d\b")
# Pages that may carry a date: the changelog is not a user page; sources.md cites publications.
DATED_PAGES = ("sources.md",)

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


def history_pages():
    """README.md and every published docs page but the changelog: the pages that describe the
    current state only."""
    return user_pages() + [ROOT / "README.md"]


def _matches(pages, pattern):
    """(page, line number, matched text, line) of every match of pattern on the pages."""
    for page in pages:
        for number, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1):
            for match in pattern.finditer(line):
                yield page, number, match.group(0), line


def _git_history_or_why_not():
    """None when ROOT is a git checkout with commits, else why the commit check cannot run."""
    if shutil.which("git") is None:
        return "git is not installed"
    probe = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--verify", "--quiet", "HEAD^{commit}"],
                           capture_output=True, text=True)
    if probe.returncode != 0:
        return f"{ROOT} is not a git checkout with history (an sdist, an export)"
    return None


def commits_of_this_repository(words):
    """The words among ``words`` that name a commit of this repository (``git cat-file -e
    WORD^{commit}`` would succeed; an abbreviation that several objects share counts too)."""
    words = sorted(set(words))
    if not words:
        return set()
    checked = subprocess.run(["git", "-C", str(ROOT), "cat-file", "--batch-check"],
                             input="".join(f"{word}^{{commit}}\n" for word in words),
                             capture_output=True, text=True, check=True)
    answers = checked.stdout.splitlines()
    assert len(answers) == len(words), checked.stdout
    return {word for word, answer in zip(words, answers)
            if not answer.endswith(" missing")}


def test_pages_name_no_commit_of_this_repository():
    why_not = _git_history_or_why_not()
    if why_not:
        pytest.skip(f"commit ids on the pages not checked: {why_not}")
    found = list(_matches(history_pages(), HEX_WORD))
    ours = commits_of_this_repository(word for _, _, word, _ in found)
    offences = [f"{_where(page, number)}: commit {word}: {line.strip()[:100]}"
                for page, number, word, line in found if word in ours]
    assert not offences, "commits of this repository named outside docs/changelog.md (say what is, " \
                         "and put what changed in the changelog):\n" + "\n".join(offences)


def test_pages_number_no_items_of_a_list_of_changes():
    offences = [f"{_where(page, number)}: '{text}': {line.strip()[:100]}"
                for page, number, text, line in _matches(history_pages(), ITEM_NUMBER)]
    assert not offences, "'item N' outside docs/changelog.md (name the thing itself, or link its " \
                         "section):\n" + "\n".join(offences)


def test_pages_carry_no_dates():
    pages = [page for page in history_pages() if page.name not in DATED_PAGES or page.parent != DOCS]
    offences = [f"{_where(page, number)}: date {text}: {line.strip()[:100]}"
                for page, number, text, line in _matches(pages, DATE)]
    assert not offences, "dates outside docs/changelog.md and docs/sources.md (history goes in the " \
                         "changelog):\n" + "\n".join(offences)


def test_a_commit_id_is_told_from_other_hex_words():
    assert HEX_WORD.findall("before 133eb79, after 9faf085's counts") == ["133eb79", "9faf085"]
    assert HEX_WORD.findall("1100000 frames, a defaced cafe, 0x01, 8a3") == []
    why_not = _git_history_or_why_not()
    if why_not:
        pytest.skip(f"commit ids not checked: {why_not}")
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True,
                          check=True).stdout.strip()
    # this repository's commit, full or abbreviated, is ours; DCPLib's commit (docs/hil.md) is not
    assert commits_of_this_repository([head, head[:9], "39e16f034ab0efd51afea5df295f5e83680c6e8c"]) == {
        head, head[:9]}


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
