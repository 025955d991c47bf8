"""mkdocs hooks: the pages generated from the code at build time.

* ``api/<area>.md``: one mkdocstrings entry for every public name of ``jaxsplit`` (read from
  the re-exports in ``jaxsplit/__init__.py``, grouped by the package that defines them, each
  once; the package's own top-level modules (``_xla_cpu``: compiler settings) form the last
  page, "Tuning"; ``DOCUMENTED_WITH`` places a name beside the one it belongs with) and for
  ``jaxsplit.diffrax``, so a new public name gets its API entry without editing the docs;
* ``schemes.md``: the scheme table, from the registry;
* ``notebooks/*.ipynb``: executed copies, rendered by mkdocs-jupyter without executing. They
  come from ``$JAXSPLIT_DOCS_NOTEBOOKS`` (a folder named ``notebooks``; the test suite executes each notebook once and points
  here), else from ``build/notebooks/`` (executed here, at reduced size, when missing or older
  than the source);
* ``audit.md``: the seed-paper audit report. It comes from ``$JAXSPLIT_DOCS_AUDIT`` (a folder
  holding an audit: the test suite runs one claim there), else from ``build/audit/``, which the
  build writes with ``jaxsplit paper`` when it is missing or older than ``jaxsplit/paper/`` (about
  95 s on 2 cores; later builds reuse it).
"""

import ast
import os
import pathlib

from mkdocs.plugins import event_priority
from mkdocs.structure.files import File

ROOT = pathlib.Path(__file__).resolve().parent.parent
AREAS = {  # package -> (title, one line on what it owns)
    "core": ("Core", "Schemes as data, flows, the composer and the stepping loop."),
    "systems": ("Systems", "The system protocol, the free rigid body, Hamilton–Poisson systems and the so(3) toolkit."),
    "checks": ("Checks", "Poisson and symplectic defects, invariants, orders, tableau conditions: for any map."),
    "classical": ("Classical methods", "Runge–Kutta methods and Ruth's method on any PyTree state."),
    "explore": ("Exploration", "Sweeps, stability maps, fitting and tuning over families of systems."),
    "paper": ("Paper audit", "The seed paper's claims re-derived numerically."),
    "measure": ("Measurements", "The dynamical structure factor S(q, ω) of spin trajectories."),
    "tuning": ("Tuning", "XLA's CPU settings, as explicit calls (importing jaxsplit changes none; the command line applies them)."),
}
# name -> the public name it is documented beside: ``splitting`` builds a ``Composition`` from a
# system's flows (it lives in ``systems`` because it asks the system for its split)
DOCUMENTED_WITH = {"splitting": "compose"}


def public_names() -> dict[str, list[str]]:
    """{area: [public names]} from the ``from .area._module import X as X`` lines of the
    ``if TYPE_CHECKING:`` block of ``jaxsplit/__init__.py`` (read statically: the package loads
    them lazily; the one list of public names), each name once."""
    tree = ast.parse((ROOT / "jaxsplit" / "__init__.py").read_text())
    block = next(node for node in tree.body if isinstance(node, ast.If))
    areas: dict[str, list[str]] = {area: [] for area in AREAS}
    placed = {}
    for node in block.body:
        if isinstance(node, ast.ImportFrom) and node.level == 1 and node.module:
            area = node.module.split(".")[0]
            area = "tuning" if area.startswith("_") else area  # the package's own top-level modules (_xla_cpu)
            for name in (alias.asname or alias.name for alias in node.names):
                if area in areas and name not in placed:
                    placed[name] = area
                    areas[area].append(name)
    for name, beside in DOCUMENTED_WITH.items():
        if name in placed and beside in placed:
            areas[placed[name]].remove(name)
            group = areas[placed[beside]]
            group.insert(group.index(beside) + 1, name)
    return {area: names for area, names in areas.items() if names}


def _api_page(area: str, names: list[str]) -> str:
    title, summary = AREAS[area]
    entries = "\n\n".join(f"::: jaxsplit.{name}" for name in names)
    return f"# {title}\n\n{summary} Every name is importable as `jaxsplit.NAME`.\n\n{entries}\n"


def _api_index(areas: dict[str, list[str]]) -> str:
    lines = ["# API reference", "", ("Every public name, by the package that defines it "
                                     "(generated from `jaxsplit/__init__.py`)."), ""]
    for area, names in areas.items():
        lines.append(f"* [{AREAS[area][0]}]({area}.md): " + ", ".join(f"`{n}`" for n in names))
    lines.append("* [diffrax](diffrax.md): `jaxsplit.diffrax` (optional extra): " + ", ".join(
        f"`{n}`" for n in _diffrax_names()))
    return "\n".join(lines) + "\n"


def _diffrax_names() -> list[str]:
    tree = ast.parse((ROOT / "jaxsplit" / "diffrax.py").read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "__all__" for t in node.targets):
            return list(ast.literal_eval(node.value))
    return []


def _scheme_table() -> str:
    import jaxsplit
    from jaxsplit.core._compose import merge, word

    lines = ["# Schemes", "", ("Generated from the registry (`jaxsplit.schemes`) when the site is built. "
                               "Sub-flows per step are counted after merging adjacent same-piece rotations, "
                               "on two and three pieces (partitioned schemes take exactly two)."), "",
             "| name | form | order | stages | sub-flows (2 pieces) | sub-flows (3 pieces) | source |",
             "|---|---|---|---|---|---|---|"]
    for name in jaxsplit.schemes:
        s = jaxsplit.schemes[name]
        counts = [str(len(merge(word(s, n)))) if s.pieces_allowed(n) else "—" for n in (2, 3)]
        lines.append(f"| `{name}` | {s.form} | {s.order} | {s.stages} | {counts[0]} | {counts[1]} | {s.citation} |")
    return "\n".join(lines) + "\n"


NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))
CELL_TIMEOUT = 600  # seconds per cell
_RUNNER = f"""
import sys, tempfile, nbformat
from jupyter_client import KernelManager
from nbclient import NotebookClient
nb = nbformat.read(sys.argv[1], as_version=4)
# IPC sockets in a folder of its own, not TCP ports: kernels started at once raced for the same
# free port ("Address already in use")
with tempfile.TemporaryDirectory() as sockets:
    km = KernelManager(kernel_name="python3", transport="ipc", ip=sockets + "/kernel")
    NotebookClient(nb, km=km, timeout={CELL_TIMEOUT}, kernel_name="python3",
                   resources={{"metadata": {{"path": sys.argv[2]}}}}).execute()
nbformat.write(nb, sys.argv[3])
"""


def execute_notebooks(sources, out: pathlib.Path, small: bool = True) -> dict:
    """Execute every notebook at once (in parallel processes: compilation is single-threaded) into
    ``out``; {name: (exit code, stderr)}. ``small`` sets JAXSPLIT_NOTEBOOK_SMALL=1 (reduced sizes).
    The kernels import ``jaxsplit`` from this checkout (PYTHONPATH), whatever is installed."""
    import subprocess
    import sys

    out.mkdir(parents=True, exist_ok=True)
    # the inline backend, so that figures are stored in the executed copy (no display is needed)
    env = dict(os.environ, MPLBACKEND="module://matplotlib_inline.backend_inline",
               PYTHONPATH=os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]),
               **({"JAXSPLIT_NOTEBOOK_SMALL": "1"} if small else {}))
    procs = {nb.name: subprocess.Popen([sys.executable, "-c", _RUNNER, str(nb), str(nb.parent), str(out / nb.name)],
                                       env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for nb in sources}
    return {name: (p.wait(timeout=900), p.communicate()[1]) for name, p in procs.items()}


def _executed_notebooks() -> pathlib.Path:
    """The folder (named ``notebooks``) holding the executed copies."""
    given = os.environ.get("JAXSPLIT_DOCS_NOTEBOOKS")
    if given:
        if pathlib.Path(given).name != "notebooks":
            raise ValueError(f"JAXSPLIT_DOCS_NOTEBOOKS must name a folder called 'notebooks', got {given}")
        return pathlib.Path(given)
    out = ROOT / "build" / "notebooks"
    stale = [nb for nb in NOTEBOOKS
             if not (out / nb.name).exists() or (out / nb.name).stat().st_mtime < nb.stat().st_mtime]
    failed = {name: err[-2000:] for name, (code, err) in execute_notebooks(stale, out).items() if code}
    if failed:
        raise RuntimeError(f"notebooks failed to execute: {failed}")
    return out


def _audit() -> pathlib.Path:
    """The folder holding the audit to show: ``$JAXSPLIT_DOCS_AUDIT``, else ``build/audit``,
    (re)written by ``jaxsplit paper`` when its report is missing or older than the audit's code."""
    import subprocess
    import sys

    given = os.environ.get("JAXSPLIT_DOCS_AUDIT")
    if given:
        return pathlib.Path(given)
    audit = ROOT / "build" / "audit"
    report = audit / "report.md"
    newest = max(p.stat().st_mtime for p in (ROOT / "jaxsplit" / "paper").rglob("*.py"))
    if not report.exists() or report.stat().st_mtime < newest:
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]))
        run = subprocess.run([sys.executable, "-m", "jaxsplit", "paper", "--out", str(audit), "--force"], env=env,
                             capture_output=True, text=True, check=False)
        if run.returncode != 0:
            raise RuntimeError(f"jaxsplit paper --out {audit} exited {run.returncode}: {run.stderr[-2000:]}")
    return audit


def _audit_page() -> tuple[str, list[pathlib.Path]]:
    audit = _audit()
    report = audit / "report.md"
    if not report.exists():
        raise FileNotFoundError(f"no audit report in {audit} (JAXSPLIT_DOCS_AUDIT must name a `jaxsplit paper` output)")
    return report.read_text(), sorted(p for p in audit.iterdir() if p.suffix in (".png", ".svg"))


@event_priority(100)  # before mkdocs-jupyter, which must see the notebook files
def on_files(files, config):
    areas = public_names()
    generated = {f"api/{area}.md": _api_page(area, names) for area, names in areas.items()}
    generated["api/index.md"] = _api_index(areas)
    generated["api/diffrax.md"] = "# jaxsplit.diffrax\n\n::: jaxsplit.diffrax\n"
    generated["schemes.md"] = _scheme_table()
    audit, figures = _audit_page()
    generated["audit.md"] = audit
    for uri, content in generated.items():
        files.append(File.generated(config, uri, content=content))
    for figure in figures:
        files.append(File.generated(config, figure.name, abs_src_path=str(figure)))
    notebooks = _executed_notebooks()
    for source in NOTEBOOKS:
        executed = notebooks / source.name
        if not executed.exists():
            raise FileNotFoundError(f"no executed copy of {source.name} in {notebooks}")
        # a plain File (not File.generated), which mkdocs-jupyter wraps: the copy's folder is "notebooks"
        files.append(File(f"notebooks/{source.name}", str(notebooks.parent), config["site_dir"],
                          config["use_directory_urls"]))
    return files
