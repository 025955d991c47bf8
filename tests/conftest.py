"""Tests run in float64: structure preservation is judged at round-off."""

import jax

jax.config.update("jax_enable_x64", True)
