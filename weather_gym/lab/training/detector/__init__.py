"""Training the cone detector: the torch network (``conenet``), the loop and export (``train``), pictures and k sweeps of a detector (``plots``)."""
