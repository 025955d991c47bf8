"""The seed paper's classical integrators (§2): Runge–Kutta methods from Butcher tableaus
(explicit, implicit, Gauss–Legendre) on any system's vector field and any PyTree state
(``_runge_kutta``), and Ruth's map (2.6) (``_ruth``)."""

from ._runge_kutta import ButcherTableau as ButcherTableau
from ._runge_kutta import CoefficientRungeKutta as CoefficientRungeKutta
from ._runge_kutta import RungeKutta as RungeKutta
from ._runge_kutta import explicit_euler as explicit_euler
from ._runge_kutta import gauss_legendre as gauss_legendre
from ._runge_kutta import gauss_legendre_tableau as gauss_legendre_tableau
from ._runge_kutta import rk4 as rk4
from ._runge_kutta import runge_kutta as runge_kutta
from ._runge_kutta import runge_kutta_coefficients as runge_kutta_coefficients
from ._runge_kutta import tableaus as tableaus
from ._runge_kutta import trapezoid as trapezoid
from ._ruth import ruth as ruth
