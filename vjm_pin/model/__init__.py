"""Model layer: the VJM URDF format and everything that writes or finds one.

Modules (one concept each):

- :mod:`~vjm_pin.model.format`: the format itself (``vjm:`` tags, springs, roles, closures,
  task) and :func:`~vjm_pin.model.format.load_vjm`.
- :mod:`~vjm_pin.model.spec`: the spring spec (YAML/JSON) reader.
- :mod:`~vjm_pin.model.beam`: beam-section stiffness matrices.
- :mod:`~vjm_pin.model.generator`: a VJM URDF from a plain URDF and a spec.
- :mod:`~vjm_pin.model.subdivide`: links split into sub-links.
- :mod:`~vjm_pin.model.robots`: the robot catalogue (example-robot-data, any URDF).
- :mod:`~vjm_pin.model.paper_models`, :mod:`~vjm_pin.model.registry`: bundled models by name.

No Pinocchio kinematics beyond building the model; nothing here imports the solver.
"""

from vjm_pin.model.format import (
    COMPONENTS,
    NS,
    ROLES,
    Closure,
    SpringGroup,
    VjmModel,
    load_vjm,
)

__all__ = ["COMPONENTS", "NS", "ROLES", "Closure", "SpringGroup", "VjmModel", "load_vjm"]
