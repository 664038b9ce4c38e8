"""Vehicles from flight-stack descriptions.

* :mod:`alloc.importers.px4` -- a PX4 parameter file (``.params`` as QGroundControl saves
  it, or an airframe file's ``param set-default`` lines): rotors (``CA_ROTORn_*``) and
  control surfaces (``CA_SV_CSn_*``), PX4's effectiveness formulas and, optionally, its
  normalisation; airframe files as PX4 ships them; tiltrotor VTOLs with a ``[schedule]``
  (:mod:`alloc.importers.px4_tiltrotor`).  ``alloc.load_vehicle("x.params")`` uses it.
* :mod:`alloc.importers.ardupilot` -- an ArduPilot motor factor table (roll, pitch, yaw,
  throttle factor per motor; a CSV or TOML table, a built-in frame by name, or a parameter file's
  ``FRAME_CLASS`` and ``FRAME_TYPE``: :mod:`alloc.importers.ardupilot_frames`).

Each returns an :class:`alloc.vehicle_file.Vehicle`; ``vehicle.save("x.toml")`` writes it as a
vehicle file.
"""
