"""Recording full-pipeline episodes for the perception surrogate and validating it (``record``, ``validate``)."""
