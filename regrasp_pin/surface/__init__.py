"""The path on the object: the paper's step 3 (section 2.1, Figs. 3-4).

Takes the object, the released contact P and the new contact Q (object frame) and a
cost per grid node. Gives:

- :mod:`.region`: which faces hold the route from P to Q (:func:`choose_region`);
- :mod:`.unfolding`: those faces unfolded into one plane (:func:`unfold_faces`);
- :mod:`.grid`: a lattice over the unfolded region (:class:`SurfaceGrid`);
- :mod:`.path`: the cheapest grid path from P to Q, weighing length and node costs
  (:class:`GridPath`, Dijkstra);
- :mod:`.inflation`: that path lifted onto the virtually inflated surface, not
  inflated at P and Q: the fingertip-centre curve (:class:`TipPath`).
"""

from .grid import FaceUnfolding, SurfaceGrid, build_surface_grid, unfold_faces
from .inflation import TipPath, grid_inflation, inflate_path, inflation_height
from .path import GridPath, shortest_grid_path
from .region import Region, choose_region

__all__ = [
    "FaceUnfolding",
    "GridPath",
    "Region",
    "SurfaceGrid",
    "TipPath",
    "build_surface_grid",
    "choose_region",
    "grid_inflation",
    "inflate_path",
    "inflation_height",
    "shortest_grid_path",
    "unfold_faces",
]
