"""Every example in a public docstring runs as a doctest (float64, from conftest), and every public
name of the finished areas carries one: the examples on the site cannot rot."""

import doctest
import inspect

import pytest
from conftest import docs_hooks

import jaxsplit
import jaxsplit.diffrax

AREAS = docs_hooks().public_names()
WITH_EXAMPLES = ("core", "systems", "checks", "classical", "explore", "paper")  # every public name: a runnable example
DATA = (dict, tuple)  # registries and constants: documented where they are defined, no docstring of their own
FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE


def public_objects() -> dict:
    objects = {"jaxsplit": jaxsplit, "jaxsplit.diffrax": jaxsplit.diffrax}
    objects |= {f"jaxsplit.{n}": getattr(jaxsplit, n) for group in AREAS.values() for n in group}
    objects |= {f"jaxsplit.diffrax.{n}": getattr(jaxsplit.diffrax, n) for n in jaxsplit.diffrax.__all__}
    seen, unique = set(), {}
    for name, obj in objects.items():  # aliases (Trajectory = Solution) once
        if id(obj) not in seen and not isinstance(obj, DATA):
            seen.add(id(obj))
            unique[name] = obj
    return unique


def doctests(name, obj):
    """The doctests of ``obj`` (a module: its own docstring; a class: with its methods')."""
    finder = doctest.DocTestFinder(recurse=not inspect.ismodule(obj), exclude_empty=True)
    if not (inspect.isclass(obj) or inspect.isroutine(obj) or inspect.ismodule(obj)):
        obj = type(obj)  # an instance (the scheme registry): its class documents it
    return [t for t in finder.find(obj, name, globs={}) if t.examples]


CASES = {name: tests for name, obj in public_objects().items() if (tests := doctests(name, obj))}


@pytest.mark.parametrize("name", sorted(CASES))
def test_docstring_examples_run(name):
    runner = doctest.DocTestRunner(optionflags=FLAGS)
    report = []
    for test in CASES[name]:
        runner.run(test, out=report.append)
    assert runner.failures == 0, "".join(report)


def test_a_wrong_example_fails():
    """Must-fail twin: the runner does compare the output."""
    test = doctest.DocTestParser().get_doctest(">>> 1 + 1\n3\n", {}, "wrong", None, 0)
    runner = doctest.DocTestRunner(optionflags=FLAGS)
    runner.run(test, out=lambda _: None)
    assert runner.failures == 1


@pytest.mark.parametrize("area", WITH_EXAMPLES + ("diffrax",))
def test_every_public_name_has_an_example(area):
    if area == "diffrax":
        names = {f"jaxsplit.diffrax.{n}": getattr(jaxsplit.diffrax, n) for n in jaxsplit.diffrax.__all__}
    else:
        names = {f"jaxsplit.{n}": getattr(jaxsplit, n) for n in AREAS[area]}
    missing = [n for n, obj in names.items() if not isinstance(obj, DATA) and n not in CASES
               and not any(id(obj) == id(o) for k, o in public_objects().items() if k in CASES)]
    assert not missing, missing
