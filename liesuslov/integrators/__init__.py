"""Lie-group integrators: tableaux (data), charts (exp, Cayley), one RKMK stepper, the front door."""

from .charts import CHARTS, Chart, make_chart
from .integrate import METHODS, Method, integrate
from .solution import Solution
from .tableaux import TABLEAUX, ButcherTableau, get_tableau

__all__ = ["integrate", "METHODS", "Method", "Solution", "ButcherTableau", "TABLEAUX", "get_tableau",
           "Chart", "CHARTS", "make_chart"]
