"""The one exception type for bad input, so callers (the CLI) can tell it from bugs."""


class InputError(ValueError):
    """A value given by the user is not allowed; the message names it and what is."""
