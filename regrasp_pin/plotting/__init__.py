"""Static matplotlib figures in the style of the paper's figures (optional extra ``viz``).

This subpackage is never imported by ``import regrasp_pin``; import the module for the
figure you need, e.g. ``from regrasp_pin.plotting.polygon import plot_polygon``.
"""

from __future__ import annotations

from typing import Any

from ..exceptions import MissingExtraError


def require_pyplot() -> Any:
    """Return ``matplotlib.pyplot`` with the non-interactive Agg backend.

    Raises:
        MissingExtraError: if matplotlib is not installed (``pip install regrasp-pin[viz]``).
    """
    try:
        import matplotlib
    except ImportError:
        raise MissingExtraError("matplotlib", "viz") from None
    if matplotlib.get_backend().lower() not in ("agg", "pdf", "svg", "ps"):
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt
