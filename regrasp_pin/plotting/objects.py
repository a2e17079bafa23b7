"""Fig. 1 of the paper: the object, its sampled surface and the contacts, in the object frame."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validate import as_array
from ..model.objects import ConvexObject, SurfaceSample
from . import require_pyplot

__all__ = ["plot_object"]


def plot_object(
    obj: ConvexObject,
    sample: SurfaceSample | None = None,
    contacts_object: np.ndarray | None = None,
    ax: Any = None,
    *,
    contact_normals_object: np.ndarray | None = None,
    normal_length_m: float | None = None,
    title: str | None = "Object in the Cartesian space (Fig. 1)",
) -> Any:
    """Draw a convex object in 3-D: translucent faces, sampled points, contacts.

    Args:
        obj: The object.
        sample: A surface sample to draw as small points (e.g. ``obj.sample_surface(s)``).
        contacts_object: Contact points in the object frame [m], shape (k, 3), drawn as
            large markers with their outward normals.
        ax: A matplotlib 3-D axes; default a new figure.
        contact_normals_object: Normals at the contacts, shape (k, 3); default the
            normal of the face each contact lies on.
        normal_length_m: Length of the drawn normals [m]; default 30 % of the object
            radius.
        title: Axes title (None for none).

    Returns:
        The matplotlib 3-D axes.

    Raises:
        MissingExtraError: if matplotlib is not installed.
        InputError: for malformed contact arrays.
    """
    plt = require_pyplot()
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    if ax is None:
        fig = plt.figure(figsize=(6, 5))
        ax = fig.add_subplot(projection="3d")
    mm = 1e3  # draw in millimetres
    polys = [f.polygon * mm for f in obj.faces]
    ax.add_collection3d(
        Poly3DCollection(
            polys,
            facecolors=(0.55, 0.7, 0.9, 0.25),
            edgecolors=(0.2, 0.3, 0.5, 0.9),
            linewidths=0.8,
        )
    )
    if sample is not None:
        pts = sample.points * mm
        ax.scatter(
            pts[:, 0],
            pts[:, 1],
            pts[:, 2],
            s=2,
            c="0.3",
            depthshade=False,
            label=f"surface points ({len(sample)}, {sample.spacing_m * mm:g} mm)",
        )
    if contacts_object is not None:
        c = as_array(contacts_object, "contacts_object", (None, 3))
        if contact_normals_object is None:
            nrm = obj.normals[obj.supporting_face(c)]
        else:
            nrm = as_array(contact_normals_object, "contact_normals_object", (c.shape[0], 3))
        length = (0.3 * obj.radius_m if normal_length_m is None else normal_length_m) * mm
        ax.scatter(
            c[:, 0] * mm,
            c[:, 1] * mm,
            c[:, 2] * mm,
            s=80,
            c="tab:red",
            depthshade=False,
            label="contacts",
        )
        ax.quiver(
            c[:, 0] * mm,
            c[:, 1] * mm,
            c[:, 2] * mm,
            nrm[:, 0],
            nrm[:, 1],
            nrm[:, 2],
            length=length,
            color="tab:red",
        )
    r = obj.radius_m * mm
    for setter in (ax.set_xlim, ax.set_ylim, ax.set_zlim):
        setter(-r, r)
    ax.set_box_aspect((1, 1, 1))
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_zlabel("z [mm]")
    if title:
        ax.set_title(title)
    if sample is not None or contacts_object is not None:
        ax.legend(loc="upper left", fontsize="small")
    return ax
