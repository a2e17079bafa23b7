"""Sub-commands of the ``regrasp-pin`` CLI, one module each (see :mod:`regrasp_pin.cli`)."""
