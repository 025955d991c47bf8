"""``jaxsplit simulate``: integrate a body and summarise the invariant errors."""

import time

import jax.numpy as jnp
import numpy as np

from .._body import PAPER_BODY, PAPER_M0, RigidBody
from .._exact import symmetric_solution
from .._integrate import integrate
from .._splitting import splitting


def add_parser(sub):
    p = sub.add_parser("simulate", help="integrate a rigid body",
                       description="Integrate the free rigid body (default: the seed paper's "
                                   "symmetric body with Lie-Trotter) and print a summary.")
    p.add_argument("--scheme", default="lie-trotter")
    p.add_argument("--dt", type=float, default=0.01)
    p.add_argument("--steps", type=int, default=10_000)
    p.set_defaults(func=run)


def run(args):
    body = RigidBody(jnp.asarray(PAPER_BODY))
    m0 = jnp.asarray(PAPER_M0)
    start = time.perf_counter()
    traj = integrate(splitting(body, args.scheme), m0, args.dt, args.steps, save_every=10)
    m = np.asarray(traj.x)
    seconds = time.perf_counter() - start
    energy = np.asarray(body.hamiltonian(traj.x))
    casimir = np.asarray(body.casimir(traj.x))
    exact = np.asarray(symmetric_solution(body, m0, traj.t))
    print(f"body I = {PAPER_BODY}, m0 = {PAPER_M0}, scheme {args.scheme}, h = {args.dt}, "
          f"{args.steps} steps (t = {float(traj.t[-1]):g}) in {seconds:.2f} s")
    print(f"  max relative energy error   {np.max(np.abs(energy / energy[0] - 1)):.3e}")
    print(f"  max relative Casimir error  {np.max(np.abs(casimir / casimir[0] - 1)):.3e}")
    print(f"  max error vs exact solution {np.max(np.abs(m - exact)):.3e}")
