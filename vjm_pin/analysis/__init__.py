"""Analysis layer: what is built from many equilibria.

- :mod:`~vjm_pin.analysis.curve`: force–deflection curves and their critical points.
- :mod:`~vjm_pin.analysis.maps`: stiffness and deflection maps over the workspace, run by
  :mod:`~vjm_pin.analysis.map_backends` (local cores or Dask).
- :mod:`~vjm_pin.analysis.indices`: scalar stiffness indices (weakest translation).
"""
