"""The path on the object: the paper's step 3 (section 2.1, Figs. 3-4).

Takes the object, the released contact P and the new contact Q (object frame) and a
cost per grid node. Gives:

- :mod:`.grid`: the faces holding P and Q unfolded into one plane and gridded
  (:class:`SurfaceGrid`);
- :mod:`.path`: the cheapest grid path from P to Q, weighing length and node costs
  (:class:`GridPath`, Dijkstra);
- :mod:`.inflation`: that path lifted onto the virtually inflated surface, not
  inflated at P and Q: the fingertip-centre curve (:class:`TipPath`).
"""

from .grid import FaceUnfolding, SurfaceGrid, build_surface_grid, unfold_faces
from .inflation import TipPath, grid_inflation, inflate_path, inflation_height
from .path import GridPath, shortest_grid_path

__all__ = [
    "FaceUnfolding",
    "GridPath",
    "SurfaceGrid",
    "TipPath",
    "build_surface_grid",
    "grid_inflation",
    "inflate_path",
    "inflation_height",
    "shortest_grid_path",
    "unfold_faces",
]
