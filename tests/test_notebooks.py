"""Every notebook runs top to bottom (reduced size: JAXSPLIT_NOTEBOOK_SMALL=1), in parallel."""

import os
import pathlib
import subprocess
import sys
import textwrap

import pytest

NOTEBOOKS = sorted((pathlib.Path(__file__).parent.parent / "notebooks").glob("*.ipynb"))
CELL_TIMEOUT = 600  # seconds per cell (nbclient)
RUNNER = textwrap.dedent(f"""
    import sys, nbformat
    from nbclient import NotebookClient
    nb = nbformat.read(sys.argv[1], as_version=4)
    NotebookClient(nb, timeout={CELL_TIMEOUT}, kernel_name="python3",
                   resources={{"metadata": {{"path": sys.argv[2]}}}}).execute()
""")


@pytest.fixture(scope="module")
def runs(request):
    """Start every selected notebook at once (compilation is single-threaded: 2 cores help);
    ``-k 04`` runs notebook 04 alone."""
    wanted = {item.callspec.params["name"] for item in request.session.items
              if getattr(item, "originalname", None) == "test_notebook_executes" and hasattr(item, "callspec")}
    env = dict(os.environ, JAXSPLIT_NOTEBOOK_SMALL="1", MPLBACKEND="Agg")
    procs = {nb.name: subprocess.Popen([sys.executable, "-c", RUNNER, str(nb), str(nb.parent)], env=env,
                                       stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for nb in NOTEBOOKS if nb.name in wanted}
    return {name: (p.wait(timeout=900), p.communicate()) for name, p in procs.items()}


def test_there_are_four_stories():
    assert len(NOTEBOOKS) >= 4


@pytest.mark.parametrize("name", [nb.name for nb in NOTEBOOKS])
def test_notebook_executes(runs, name):
    code, (_out, err) = runs[name]
    assert code == 0, err[-4000:]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.name)
def test_notebooks_are_stored_without_outputs(path):
    import nbformat

    nb = nbformat.read(path, as_version=4)
    assert all(not c.get("outputs") and c.get("execution_count") is None
               for c in nb.cells if c.cell_type == "code")
