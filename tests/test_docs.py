"""The documentation site builds with warnings as errors, has the API entry of every public name,
renders the executed notebooks, and fails on a broken cross-reference."""

import os
import pathlib
import re
import subprocess
import sys
import textwrap
import time

import pytest
from conftest import ROOT, docs_hooks

pytestmark = pytest.mark.xdist_group("notebooks")  # one worker executes the notebooks once, for both files

import jaxsplit


def mkdocs_build(config: pathlib.Path, site: pathlib.Path, env=None):
    """(exit code, output, seconds) of ``mkdocs build --strict``."""
    start = time.perf_counter()
    run = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(config), "-d", str(site)],
                         check=False, capture_output=True, text=True,
                         env=dict(os.environ, NO_MKDOCS_2_WARNING="1", **(env or {})),
                         cwd=config.parent, timeout=600)
    return run.returncode, run.stdout + run.stderr, time.perf_counter() - start


AUDIT_CLAIM = "stages"  # one claim of the audit (a fraction of a second): the page shows its report


@pytest.fixture(scope="module")
def site(executed_notebooks, tmp_path_factory):
    from jaxsplit.cli import main

    folder, runs = executed_notebooks
    if any(code for code, _ in runs.values()):
        pytest.fail("a notebook failed to execute (see test_notebooks); the site renders executed copies")
    audit = tmp_path_factory.mktemp("audit") / "audit"
    assert main(["paper", "--out", str(audit), "--claims", AUDIT_CLAIM]) == 0
    out = tmp_path_factory.mktemp("site")
    code, log, seconds = mkdocs_build(ROOT / "mkdocs.yml", out, {"JAXSPLIT_DOCS_NOTEBOOKS": str(folder),
                                                                 "JAXSPLIT_DOCS_AUDIT": str(audit)})
    print(f"mkdocs build --strict: {seconds:.1f} s")
    return code, log, out


def test_the_site_builds_strict(site):
    code, log, _ = site
    assert code == 0, log[-4000:]


def test_every_public_name_has_its_api_entry(site):
    _, _, out = site
    areas = docs_hooks().public_names()
    names = [n for group in areas.values() for n in group]
    assert len(names) > 50 and all(hasattr(jaxsplit, n) for n in names)
    missing = [f"{area}: {n}" for area, group in areas.items() for n in group
               if f'id="jaxsplit.{n}"' not in (out / "api" / area / "index.html").read_text()]
    diffrax_html = (out / "api" / "diffrax" / "index.html").read_text()
    missing += [n for n in docs_hooks()._diffrax_names() if f'id="jaxsplit.diffrax.{n}"' not in diffrax_html]
    assert not missing


def test_every_public_name_is_listed_where_the_api_pages_look():
    """The API pages read the ``from .area._module import X as X`` lines; a public name defined
    any other way would be missing from the site."""
    listed = {n for group in docs_hooks().public_names().values() for n in group}
    public = {n for n, obj in vars(jaxsplit).items() if not n.startswith("_") and not isinstance(obj, type(os))
              and getattr(obj, "__module__", "jaxsplit").startswith("jaxsplit")}  # not importlib's helpers
    assert not public - listed, public - listed


def test_the_navigation_lists_every_notebook_and_api_page():
    """Issue 31: notebook 04 was missing from the navigation (a page outside it is still built, so
    the strict build did not notice)."""
    nav = (ROOT / "mkdocs.yml").read_text()
    pages = [f"notebooks/{nb.name}" for nb in docs_hooks().NOTEBOOKS]
    pages += [f"api/{area}.md" for area in docs_hooks().public_names()] + ["api/index.md", "api/diffrax.md"]
    assert [p for p in pages if f"- {p}" not in nav] == []


def test_api_pages_list_each_name_once_tuning_last_splitting_with_compose():
    areas = docs_hooks().public_names()
    names = [n for group in areas.values() for n in group]
    assert len(names) == len(set(names))
    assert list(areas)[-1] == "tuning" and "compiler_options" in areas["tuning"]
    assert areas["core"].index("splitting") == areas["core"].index("compose") + 1
    assert not any(n in areas["core"] for n in areas["tuning"])


def test_generated_pages(site):
    _, _, out = site
    audit = (out / "audit" / "index.html").read_text()
    assert AUDIT_CLAIM in audit and "corrected" in audit and "Run it, then rebuild" not in audit  # the report
    table = (out / "schemes" / "index.html").read_text()
    assert all(f"<code>{name}</code>" in table for name in jaxsplit.schemes)
    for notebook in (out / "notebooks").iterdir():
        html = (notebook / "index.html").read_text()
        assert "jp-OutputArea-output" in html, notebook.name  # rendered with its outputs
    assert sum((n / "index.html").read_text().count("<img") for n in (out / "notebooks").iterdir()) >= 3
    architecture = (out / "architecture" / "index.html").read_text()
    assert re.search(r'href="\.\./api/core/#jaxsplit\.integrate"', architecture)  # cross-references resolved


MINIMAL = textwrap.dedent("""
    site_name: reference check
    docs_dir: pages
    plugins:
      - autorefs
      - mkdocstrings:
          handlers:
            python:
              paths: [{root}]
              options: {{docstring_style: null, show_source: false}}
""")


def test_a_broken_cross_reference_fails_the_strict_build(tmp_path):
    """The same one-page site builds with a valid reference and fails with a broken one."""
    (tmp_path / "pages").mkdir()
    (tmp_path / "mkdocs.yml").write_text(MINIMAL.format(root=ROOT))
    page = tmp_path / "pages" / "index.md"
    page.write_text("# API\n\nSee [integrate][jaxsplit.integrate].\n\n::: jaxsplit.integrate\n")
    code, log, _ = mkdocs_build(tmp_path / "mkdocs.yml", tmp_path / "site")
    assert code == 0, log[-3000:]
    page.write_text(page.read_text() + "\nAnd [nothing][jaxsplit.no_such_name].\n")
    code, log, _ = mkdocs_build(tmp_path / "mkdocs.yml", tmp_path / "site")
    assert code != 0 and "jaxsplit.no_such_name" in log
