"""Sampling shared by the audit's sections: random states and step sizes, worst defect over them."""

import math
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from ..systems._rigid_body import PAPER_BODY, RigidBody

N_SAMPLES = 256
H_RANGE = (1e-3, 1.0)


def scalar(x) -> float:
    return float(np.asarray(x))


def samples(dim, seed, n=N_SAMPLES, scale=1.0):
    return scale * jax.random.normal(jax.random.PRNGKey(seed), (n, dim))


def log_steps(seed, n=N_SAMPLES, lo=H_RANGE[0], hi=H_RANGE[1]):
    """Step sizes log-uniform in [lo, hi]."""
    u = jax.random.uniform(jax.random.PRNGKey(seed), (n,), minval=math.log(lo), maxval=math.log(hi))
    return jnp.exp(u)


def max_defect(defect: Callable, xs, hs) -> float:
    """max over samples of ``defect(x, h)``: one compilation."""
    return scalar(jnp.max(jax.jit(jax.vmap(defect))(xs, hs)))


def paper_body():
    return RigidBody(jnp.asarray(PAPER_BODY))
