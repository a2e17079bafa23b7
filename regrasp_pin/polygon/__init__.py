"""Polygonal approximation of a curve: the paper's step 4 (section 2.2, Eqs. 5-10).

Takes a curve ``(n, d)`` and the number of vertices m. Gives a
:class:`PolygonResult` (vertex indices into the curve, the vertices, the deviation):

- :mod:`.approximate`: the public entry, :func:`approximate_polygon`;
- :mod:`.hopfield`: the competitive (winner-take-all) Hopfield network of Eqs. 5-10;
- :mod:`.hopfield_search`: the network run from several states, with local search;
- :mod:`.exact`: the exact optimum by dynamic programming (the reference);
- :mod:`.deviation`: the deviation of each chord from its arc (Eq. 7 and variants).
"""

from .approximate import PolygonResult, approximate_polygon
from .deviation import deviation_matrix
from .exact import ExactResult, exact_polygon
from .hopfield_search import HopfieldResult, competitive_hopfield

__all__ = [
    "ExactResult",
    "HopfieldResult",
    "PolygonResult",
    "approximate_polygon",
    "competitive_hopfield",
    "deviation_matrix",
    "exact_polygon",
]
