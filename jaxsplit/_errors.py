"""The one exception type for bad input, so callers (the CLI) can tell it from bugs."""


class InputError(ValueError):
    """A value given by the user is not allowed; the one-line message names it and what is.

    A ``ValueError``, so generic handlers still catch it; the command line turns it into one
    line on stderr and exit status 2.

    >>> import jaxsplit
    >>> try:
    ...     jaxsplit.schemes["strang2"]
    ... except jaxsplit.InputError as err:
    ...     print(err)
    unknown scheme 'strang2'; did you mean strang? (`jaxsplit schemes` lists them)
    """


InputError.__module__ = "jaxsplit"  # tracebacks name the public class: jaxsplit.InputError
