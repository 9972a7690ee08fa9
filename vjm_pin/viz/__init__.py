"""Visualisation layer: meshcat pages (:mod:`~vjm_pin.viz.viewer`) and matplotlib plots
(:mod:`~vjm_pin.viz.plots`). Imports the analysis layer, never the other way round."""
