"""Schemes are frozen, hashable, validated data; the registry resolves and suggests names."""

import dataclasses
import math

import pytest

import jaxsplit
from jaxsplit import InputError, Scheme

REQUIRED = [
    "lie-trotter", "lie-trotter-adjoint", "strang", "triple-jump-4", "triple-jump-6", "suzuki-5",
    "mclachlan-ss5", "yoshida-6a", "kahan-li-6", "mclachlan-ss15", "kahan-li-8", "kahan-li-10",
    "sofroniou-spaletta-10", "mclachlan-m4", "blanes-moan-s6", "blanes-moan-s10",
    "blanes-moan-s6-prk", "blanes-moan-s10-prk",
]
CONSISTENCY_TOL = 1e-14


@pytest.mark.parametrize("name", REQUIRED)
def test_required_schemes_are_registered_and_consistent(name):
    scheme = jaxsplit.schemes[name]
    assert scheme.name == name and scheme.citation
    sums = ([math.fsum(scheme.coefficients[0::2]), math.fsum(scheme.coefficients[1::2])]
            if scheme.form == "partitioned" else [math.fsum(scheme.coefficients)])
    assert all(abs(s - 1) <= CONSISTENCY_TOL for s in sums)
    hash(scheme)


def test_schemes_are_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        jaxsplit.schemes["strang"].order = 4


def test_symmetry_is_computed_from_the_composition():
    assert not jaxsplit.schemes["lie-trotter"].symmetric
    assert all(jaxsplit.schemes[n].symmetric for n in REQUIRED if not n.startswith("lie-trotter"))


@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_recursive_triple_jump_has_3_to_the_n_strang_stages(n):
    scheme = jaxsplit.triple_jump(2 * n + 2)
    assert scheme.stages == 3**n
    for k in range(3, 2 * n + 2, 2):  # Σγ^k = 0, relative to the size of the terms
        residual = math.fsum(c**k for c in scheme.coefficients)
        assert abs(residual) <= CONSISTENCY_TOL * sum(abs(c) ** k for c in scheme.coefficients)


@pytest.mark.parametrize("kwargs, message", [
    ({"coefficients": (0.5, 0.4)}, "sum to 1"),
    ({"coefficients": (0.7, 0.3)}, "palindrome"),
    ({"order": 3}, "even order"),
    ({"order": 4, "coefficients": (0.25, 0.5, 0.25)}, r"Σγ\^3"),
    ({"form": "magic"}, "form must be"),
    ({"name": "Not Kebab"}, "kebab"),
    ({"coefficients": (float("nan"),)}, "finite"),
    ({"form": "partitioned", "coefficients": (0.5, 1.0)}, "odd in number"),
    ({"form": "lie-adjoint", "order": 1, "coefficients": (1.0,)}, "even number"),
])
def test_invalid_schemes_are_refused(kwargs, message):
    fields = {"name": "bad", "order": 2, "form": "symmetric", "coefficients": (1.0,)}
    fields.update(kwargs)
    with pytest.raises(InputError, match=message):
        Scheme(**fields)


def test_valid_user_scheme_can_be_registered_and_used():
    registry = jaxsplit.core._schemes.SchemeRegistry()
    scheme = registry.register(Scheme("my-strang", 2, "lie-adjoint", (0.5, 0.5)))
    assert registry["my-strang"] is scheme and "my-strang" in list(registry)


def test_unknown_name_suggests_the_nearest():
    with pytest.raises(InputError, match="did you mean strang"):
        jaxsplit.schemes["strnag"]
    assert "triple-jump-14" in jaxsplit.schemes and "triple-jump-5" not in jaxsplit.schemes
    assert "triple-jump-16" not in jaxsplit.schemes  # 3^7 stages: over the bound (tests/test_validation.py)


def test_partitioned_scheme_refuses_three_pieces():
    body = jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True)
    with pytest.raises(InputError, match="exactly 2 pieces"):
        jaxsplit.splitting(body, "blanes-moan-s6-prk", split="axes")
