"""What a run derives from a flow or a composition, built once per object and choice.

``integrate`` makes a ``Composition`` fastest for each run (``for_run``), and a user calling
it in a loop passes the same step every time. Building the prepared flows anew cost more
than the run itself on small problems (equinox converts and checks every field: 0.4 ms of
a 0.7 ms call of 10 Blanes–Casas–Murua 8 steps on 256 bodies). The choices are discrete (a
kernel, a polynomial bound, a layout), so the prepared object is remembered per owner and
choice: weakly (it goes with its owner) and at most ``KEPT`` choices per owner.
"""

import weakref

KEPT = 16
_BY_OWNER: dict[int, tuple[weakref.ref, dict]] = {}


def derived(owner, key, build):
    """``build()`` for ``owner`` and the hashable ``key`` (everything the result depends on
    besides ``owner``), built the first time and remembered while ``owner`` lives."""
    entry = _BY_OWNER.get(id(owner))
    if entry is None or entry[0]() is not owner:
        ident = id(owner)
        entry = (weakref.ref(owner, lambda _: _BY_OWNER.pop(ident, None)), {})
        _BY_OWNER[ident] = entry
    built = entry[1]
    if key not in built:
        value = build()  # may remember other things of the same owner
        built[key] = value
        while len(built) > KEPT:  # the oldest goes first
            built.pop(next(iter(built)))
        return value
    return built[key]


def remembered() -> int:
    """How many owners have derived objects remembered (for tests)."""
    return len(_BY_OWNER)
