"""Tests run in float64: structure preservation is judged at round-off."""

import importlib.util
import pathlib

import jax
import pytest

jax.config.update("jax_enable_x64", True)

ROOT = pathlib.Path(__file__).resolve().parent.parent


def docs_hooks():
    """``docs/hooks.py`` (the site's generated pages and the notebook executor) as a module."""
    spec = importlib.util.spec_from_file_location("jaxsplit_docs_hooks", ROOT / "docs" / "hooks.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="session")
def executed_notebooks(tmp_path_factory):
    """Every notebook executed once per session at reduced size, all at once, into a folder
    ``notebooks``: (folder, {name: (exit code, stderr)}). The notebook test checks the runs;
    the docs build renders the executed copies instead of executing them again."""
    hooks = docs_hooks()
    out = tmp_path_factory.mktemp("executed") / "notebooks"
    return out, hooks.execute_notebooks(hooks.NOTEBOOKS, out)
