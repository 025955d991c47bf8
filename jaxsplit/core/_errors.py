"""``InputError`` for the core modules; defined in ``jaxsplit/_errors.py``, which imports
nothing, so that the command line can catch it before JAX is loaded."""

from .._errors import InputError  # noqa: F401  (re-exported)
