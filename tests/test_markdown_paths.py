"""Every file the Markdown documentation points to is in the repository (issue 13).

Checked in README.md, benchmarks/README.md, benchmarks/results/*.md and docs/*.md:
* Markdown links ``[text](target)`` that are not web addresses or anchors;
* code spans and plain-text paths that name a repository path: a span whose first component is a directory of
  the repository (seen from the document or from the root), or a bare ``*.py``/``*.md``/
  ``*.ipynb`` file name, must match a file (glob patterns allowed);
* nothing may point outside the repository (``../``, ``shared/``).
Names of files the tools write (``DIR/claims.json``, ``jaxsplit-runs/…``) start with no
repository directory and are not checked.
"""

import fnmatch
import os
import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCUMENTS = sorted([ROOT / "README.md", *(ROOT / "benchmarks").glob("README.md"),
                    *(ROOT / "benchmarks" / "results").glob("*.md"), *(ROOT / "docs").glob("*.md")])
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
CODE_SPAN = re.compile(r"`([^`\s]+)`")
PLAIN_PATH = re.compile(r"(?<![\w/.:-])([\w.-]+/[\w./{},*-]*[\w*}])")  # a/b anywhere in the prose
SOURCE_SUFFIXES = (".py", ".md", ".ipynb")
OUTSIDE = ("../", "shared/", "/work/", "/tmp/")


def _repository_files() -> set[str] | None:
    """Files committed or about to be (``git ls-files``: tracked plus untracked and not ignored), as
    paths from the root; None outside a git checkout. A file that exists only here (ignored, e.g.
    a benchmark's smoke output) is not in a fresh clone, so a document must not point to it."""
    try:
        listed = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                                capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return None
    return set(listed.splitlines())


FILES = _repository_files()


def _in_repository(path: Path) -> bool:
    """``path`` (absolute: a file, a directory or a glob pattern) names something a clone has."""
    if not path.is_relative_to(ROOT):
        return False
    rel = str(path.relative_to(ROOT))
    if FILES is None:
        return bool(list(ROOT.glob(rel)))
    return any(fnmatch.fnmatchcase(f, rel) or f.startswith(rel + "/") for f in FILES)


def _site_pages() -> set[str]:
    """Pages the documentation site generates at build time (listed in mkdocs.yml's nav)."""
    return set(re.findall(r"([\w/.-]+\.(?:md|ipynb))", (ROOT / "mkdocs.yml").read_text()))


def _expand(path: str) -> list[str]:
    """``a.{md,json}`` -> ``a.md``, ``a.json``."""
    brace = re.search(r"\{([^{}]*)\}", path)
    if not brace:
        return [path]
    return [q for alt in brace.group(1).split(",")
            for q in _expand(path[:brace.start()] + alt + path[brace.end():])]


def _exists(path: str, base: Path) -> bool:
    path = re.sub(r"<[^<>/]+>", "*", path.split("#")[0].split("::")[0].rstrip("/"))  # results/<script>.md
    if "{" in path:
        return all(_exists(p, base) for p in _expand(path))
    if base == ROOT / "docs" and path in _site_pages():
        return True
    return any(_in_repository(Path(os.path.normpath(root / path))) for root in (base, ROOT))


def _names_repo_path(span: str, base: Path) -> bool:
    span = span.rstrip(".,;:").removeprefix("./")
    if "/" in span:
        first = span.split("/")[0]
        return bool(first) and any((root / first).is_dir() for root in (base, ROOT))
    return span.endswith(SOURCE_SUFFIXES) and re.fullmatch(r"[\w.-]+", span) is not None


def _missing(document: Path) -> list[str]:
    text = document.read_text()
    base = document.parent
    bad = []
    for target in LINK.findall(text):
        if target.startswith(("http://", "https://", "mailto:", "#")):
            continue
        if target.startswith(OUTSIDE) or not _exists(target, base):
            bad.append(f"link {target}")
    spans = CODE_SPAN.findall(text)
    prose = PLAIN_PATH.findall(CODE_SPAN.sub(" ", LINK.sub(" ", text)))
    spans += [p for p in prose if "." in p.rsplit("/", 1)[-1] and p not in spans]  # a/b.ext, not "NumPy/JAX"
    for span in spans:
        if span.startswith(OUTSIDE) or "/shared/" in span:
            bad.append(f"outside the repository: {span}")
        elif _names_repo_path(span, base):
            name = span.rstrip(".,;:").removeprefix("./")
            if "/" in name and not _exists(name, base):
                bad.append(f"path {name}")
            elif "/" not in name and not _in_repository(ROOT / "**" / name) and not _in_repository(ROOT / name):
                bad.append(f"file {name}")
    return bad


@pytest.mark.parametrize("document", DOCUMENTS, ids=[str(d.relative_to(ROOT)) for d in DOCUMENTS])
def test_every_path_in_the_documentation_is_in_the_repository(document):
    assert _missing(document) == []


def test_the_checker_catches_a_missing_file(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("see [the table](results/nowhere.md), `shared/reference/coefficients.md`, "
                    "`tests/no_such_test.py`, `no_such_module.py` and (results/gone.md); `DIR/claims.json` is an "
                    "output, https://example.org/results/x.md a web page")
    (tmp_path / "results").mkdir()
    assert len(_missing(page)) == 5, _missing(page)


@pytest.mark.skipif(FILES is None, reason="not a git checkout")
def test_a_file_that_only_this_checkout_has_does_not_count():
    """What exists here but is not committed (ignored outputs, git's own files) is missing in a fresh
    clone: CI saw a README name a benchmark's smoke output that was on disk only here."""
    here_only = ROOT / ".git"  # a folder in a clone, a file in a worktree
    assert here_only.exists() and not _in_repository(here_only)
    assert _in_repository(ROOT / "README.md") and _in_repository(ROOT / "benchmarks" / "*.py")
