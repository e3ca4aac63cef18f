"""Lie-group integrators: tableaux and stage plans (data), charts, the controller, two solvers, the front door.

``integrate`` validates a call into a :class:`~.problem.Problem`; the compiled kernel (:mod:`.kernel`,
numba, optional) or the numpy reference (:mod:`.solve_numpy`) solves each trajectory on its own, with
output and events on the method's continuous extension; a :class:`Solution` comes back.
"""

from .charts import CHARTS, Chart, make_chart
from .events import EventRecord, LinearEvent, coordinate_plane, gamma_crossing, return_plane
from .integrate import METHODS, Method, integrate
from .plan import StagePlan, make_plan
from .solution import Solution
from .tableaux import TABLEAUX, ButcherTableau, get_tableau

__all__ = ["integrate", "METHODS", "Method", "Solution", "ButcherTableau", "TABLEAUX", "get_tableau",
           "Chart", "CHARTS", "make_chart", "StagePlan", "make_plan", "EventRecord", "LinearEvent",
           "coordinate_plane", "gamma_crossing", "return_plane"]
