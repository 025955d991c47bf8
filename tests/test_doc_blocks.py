"""Every code block of README.md and docs/*.md runs (issue 31, section 5): the examples a reader
copies cannot rot.

A document's blocks run in order in one namespace and one temporary working directory (a later
block uses the names and files of an earlier one):

* ``python`` blocks are executed;
* ``bash`` blocks are ``jaxsplit …`` / ``python -m jaxsplit …`` command lines, run in-process
  through ``jaxsplit.cli.main`` (no interpreter start per line) and expected to exit 0; any other
  shell line makes the test fail (mark the block instead).

A block is preceded (on the line before its fence) by a marker where it is not run as written:
``<!-- not run: REASON -->`` (installs, the whole test suite, a long audit: the reason is
required), or ``<!-- run reduced: OLD => NEW; ... -->`` (textual substitutions that shrink a run,
e.g. ``--t-end 500 => --t-end 5``; each must match).
"""

import pathlib
import re
import shlex

import pytest
from conftest import ROOT

DOCUMENTS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
FENCE = re.compile(r"^(?P<indent>[ \t]*)```(?P<lang>[^\n`]*)\n(?P<body>.*?)^(?P=indent)```[ \t]*$", re.MULTILINE | re.DOTALL)
MARKER = re.compile(r"^<!--\s*(?P<kind>not run|run reduced)\s*:\s*(?P<text>.*?)\s*-->$")
RUNNABLE = ("python", "bash")


class Block:
    def __init__(self, document: pathlib.Path, text: str, match: re.Match):
        self.document = document
        self.line = text.count("\n", 0, match.start()) + 1
        self.lang = match["lang"].strip()
        self.body = re.sub(rf"(?m)^{match['indent']}", "", match["body"])
        before = text[:match.start()].rstrip().rsplit("\n", 1)[-1].strip()
        self.marker = MARKER.match(before)

    @property
    def where(self) -> str:
        name = self.document.relative_to(ROOT) if self.document.is_relative_to(ROOT) else self.document.name
        return f"{name}:{self.line}"

    def source(self) -> str:
        """The body with a ``run reduced`` marker's substitutions applied (each must match)."""
        body = self.body
        if self.marker and self.marker["kind"] == "run reduced":
            for rule in self.marker["text"].split(";"):
                old, new = (part.strip() for part in rule.split("=>"))
                assert old in body, f"{self.where}: the reduction {old!r} matches nothing in the block"
                body = body.replace(old, new)
        return body


def blocks(document: pathlib.Path) -> list[Block]:
    text = document.read_text()
    return [Block(document, text, m) for m in FENCE.finditer(text)]


def jaxsplit_argv(line: str, where: str) -> list[str] | None:
    """The argument list of a ``jaxsplit …`` or ``python -m jaxsplit …`` line (None: blank or a comment)."""
    words = shlex.split(line, comments=True)
    if not words:
        return None
    if words[0] == "jaxsplit":
        return words[1:]
    if words[:3] == ["python", "-m", "jaxsplit"]:
        return words[3:]
    raise AssertionError(f"{where}: the shell line {line!r} is not a jaxsplit command; mark the block "
                         "'<!-- not run: REASON -->' or make it one")


def run_blocks(document_blocks: list[Block], capsys) -> list[str]:
    """Run the blocks in order (one namespace); the blocks run, by location."""
    from jaxsplit.cli import main

    namespace: dict = {"__name__": "__doc_block__"}
    ran = []
    for block in document_blocks:
        if block.marker and block.marker["kind"] == "not run":
            continue
        source = block.source()
        if block.lang == "python":
            exec(compile(source, block.where, "exec"), namespace)  # noqa: S102  (the documentation's own code)
        elif block.lang == "bash":
            for line in source.replace("\\\n", " ").splitlines():  # a shell line continued with a backslash
                argv = jaxsplit_argv(line, block.where)
                if argv is None:
                    continue
                code = main(argv)
                out = capsys.readouterr()
                assert code == 0, f"{block.where}: jaxsplit {shlex.join(argv)} exited {code}\n{out.out[-2000:]}{out.err[-2000:]}"
        ran.append(block.where)
    return ran


ALL = {d.relative_to(ROOT).as_posix(): blocks(d) for d in DOCUMENTS}


def test_every_block_is_runnable_or_says_why_not():
    problems = []
    for found in ALL.values():
        for block in found:
            if block.lang not in RUNNABLE:
                problems.append(f"{block.where}: fence language {block.lang!r} (use python or bash)")
            if block.marker and block.marker["kind"] == "not run" and len(block.marker["text"]) < 10:
                problems.append(f"{block.where}: 'not run' needs its reason")
    assert not problems, problems
    assert sum(len(b) for b in ALL.values()) >= 10  # the parser finds the blocks


@pytest.mark.parametrize("name", [n for n, found in ALL.items() if found])
def test_the_blocks_of_a_document_run(name, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    ran = run_blocks(ALL[name], capsys)
    assert ran or all(b.marker for b in ALL[name])


def test_a_failing_block_fails(tmp_path, monkeypatch, capsys):
    """Must-fail twins: a wrong Python block, a failing command, a stray shell line, a stale reduction."""
    monkeypatch.chdir(tmp_path)
    cases = {
        "```python\nassert 1 + 1 == 3\n```\n": AssertionError,
        "```bash\njaxsplit simulate --dt nope\n```\n": AssertionError,
        "```bash\nrm -rf build\n```\n": AssertionError,
        "<!-- run reduced: --steps 100 => --steps 1 -->\n```bash\njaxsplit schemes\n```\n": AssertionError,
    }
    for k, (text, error) in enumerate(cases.items()):
        page = tmp_path / f"page{k}.md"
        page.write_text(text)
        with pytest.raises(error):
            run_blocks([Block(page, text, m) for m in FENCE.finditer(text)], capsys)
