"""Every notebook runs top to bottom (reduced size: JAXSPLIT_NOTEBOOK_SMALL=1), in parallel;
the executed copies are kept for the docs build (``conftest.executed_notebooks``)."""

import pathlib

import pytest

NOTEBOOKS = sorted((pathlib.Path(__file__).parent.parent / "notebooks").glob("*.ipynb"))

pytestmark = pytest.mark.xdist_group("notebooks")  # one worker executes the notebooks once, for both files


def test_there_are_four_stories():
    assert len(NOTEBOOKS) >= 4


@pytest.mark.parametrize("name", [nb.name for nb in NOTEBOOKS])
def test_notebook_executes(executed_notebooks, name):
    _, runs = executed_notebooks
    code, err = runs[name]
    assert code == 0, err[-4000:]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.name)
def test_notebooks_are_stored_without_outputs(path):
    import nbformat

    nb = nbformat.read(path, as_version=4)
    assert all(not c.get("outputs") and c.get("execution_count") is None
               for c in nb.cells if c.cell_type == "code")
