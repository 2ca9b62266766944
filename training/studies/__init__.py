"""Studies behind the choices in ``docs/results.md``: calibration, the kinematic prior, seeds
(``python -m training.studies.<name>``)."""
